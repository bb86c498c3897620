// SPDX-License-Identifier: LGPL-2.1-or-later
// Nodal outward area vectors of hexahedron faces (mesh::nodal_area_vectors): on a distorted
// hexahedron with non-planar faces they must integrate linear functions exactly over the closed
// surface, sum_f sum_v a_v (x) X_v = V 1 (divergence theorem), which the particle gradient
// correction relies on; a quarter of the face area vector does not.
#include <shard/mesh/discretization.h>

#include <deal.II/dofs/dof_handler.h>
#include <deal.II/fe/fe_q.h>
#include <deal.II/fe/fe_system.h>
#include <deal.II/grid/grid_generator.h>
#include <deal.II/grid/tria.h>

#include <gtest/gtest.h>

TEST(NodalAreaVectors, IntegrateLinearFunctionsOnDistortedHex)
{
  using namespace dealii;
  Triangulation<3> tria;
  GridGenerator::hyper_cube(tria, 0., 1.);
  // Move every vertex by a fixed, different offset: non-planar faces, no symmetry.
  const double offsets[8][3] = {{0.10, -0.05, 0.02}, {-0.08, 0.07, -0.03}, {0.04, 0.09, 0.06},
                                {-0.06, -0.02, 0.11}, {0.03, 0.05, -0.09}, {0.12, -0.07, 0.04},
                                {-0.04, 0.02, 0.08},  {0.07, 0.10, -0.05}};
  for (unsigned int v = 0; v < 8; ++v)
    for (unsigned int c = 0; c < 3; ++c)
      tria.begin_active()->vertex(v)[c] += offsets[v][c];
  FESystem<3>   fe(FE_Q<3>(1), 3);
  DoFHandler<3> dof(tria);
  dof.distribute_dofs(fe);
  const auto cell = dof.begin_active();

  Tensor<2, 3> nodal, quarter;
  Tensor<1, 3> closed;
  for (const unsigned int f : cell->face_indices())
    {
      const auto         a    = shard::mesh::nodal_area_vectors(cell, f);
      const Tensor<1, 3> area = shard::mesh::outward_area_vector(cell, f);
      for (unsigned int v = 0; v < 4; ++v)
        {
          const Point<3> &x = cell->face(f)->vertex(v);
          nodal += outer_product(a[v], Tensor<1, 3>(x));
          quarter += outer_product(0.25 * area, Tensor<1, 3>(x));
          closed += a[v];
        }
      // The nodal vectors add up to the face's area vector where that one is exact, and point outward.
      EXPECT_GT((a[0] + a[1] + a[2] + a[3]) * area, 0.);
    }
  const double volume = cell->measure();
  double       err = 0, err_quarter = 0;
  for (unsigned int i = 0; i < 3; ++i)
    {
      EXPECT_NEAR(closed[i], 0., 1e-15);
      for (unsigned int j = 0; j < 3; ++j)
        {
          // int x_j n_i dA over the closed surface = V delta_ij (a (x) X stores n_i x_j).
          err         = std::max(err, std::abs(nodal[i][j] - (i == j ? volume : 0.)));
          err_quarter = std::max(err_quarter, std::abs(quarter[i][j] - (i == j ? volume : 0.)));
        }
    }
  EXPECT_LT(err, 1e-14);
  EXPECT_GT(err_quarter, 1e-4); // the quarter shares are not exact on this hexahedron
}
