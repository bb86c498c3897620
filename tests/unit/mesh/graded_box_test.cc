// SPDX-License-Identifier: LGPL-2.1-or-later
// Cell sizes of the graded box (mesh::graded_cell_sizes): they fill the edge exactly, the fine
// core has uniform cells no larger than h, the cells outside grow by at most the ratio per cell
// and never exceed the unscaled geometric size h r^k. Boxes and rods in the merged mesh are
// deal.II's subdivided_hyper_rectangle bit for bit.
#include <shard/base/parameters.h>
#include <shard/materials/material_library.h>
#include <shard/mesh/discretization.h>

#include <support/scene_text.h>

#include <deal.II/base/parameter_handler.h>
#include <deal.II/grid/grid_generator.h>
#include <deal.II/grid/tria.h>

#include <gtest/gtest.h>

#include <array>
#include <functional>
#include <map>
#include <numeric>

namespace
{
  void
  check(const double lower, const double upper, const double fl, const double fu, const double h, const double r)
  {
    const auto sizes = shard::mesh::graded_cell_sizes(lower, upper, fl, fu, h, r);
    ASSERT_FALSE(sizes.empty());
    EXPECT_NEAR(std::accumulate(sizes.begin(), sizes.end(), 0.), upper - lower, 1e-12 * (upper - lower));
    double x = lower;
    std::vector<double> core;
    for (const double s : sizes)
      {
        EXPECT_GT(s, 0.);
        if (x >= fl - 1e-12 && x + s <= fu + 1e-12)
          core.push_back(s);
        x += s;
      }
    ASSERT_FALSE(core.empty());
    for (const double s : core)
      {
        EXPECT_LE(s, h * (1 + 1e-12));
        EXPECT_NEAR(s, core.front(), 1e-12 * h);
      }
    EXPECT_NEAR(std::accumulate(core.begin(), core.end(), 0.), fu - fl, 1e-9 * h);
    for (std::size_t i = 1; i < sizes.size(); ++i)
      {
        const double q = sizes[i] / sizes[i - 1];
        EXPECT_LE(q, r * (1 + 1e-9));
        EXPECT_GE(q, 1 / r * (1 - 1e-9));
      }
    EXPECT_LE(*std::max_element(sizes.begin(), sizes.end()), h * std::pow(r, sizes.size()));
  }
} // namespace

TEST(GradedBox, FillsTheEdgeWithAUniformCoreAndBoundedGrowth)
{
  check(-0.305, 0.305, -0.08, 0.08, 0.006, 1.2); // the Hanchak slab's plan
  check(0., 1., 0.3, 0.5, 0.01, 1.05);            // off-centre core
  check(0., 1., 0., 0.5, 0.01, 1.5);              // core at one end: one growing side
}

TEST(GradedBox, RatioOneIsUniform)
{
  const auto sizes = shard::mesh::graded_cell_sizes(0., 1., 0.2, 0.4, 0.1, 1.);
  ASSERT_EQ(sizes.size(), 10u);
  for (const double s : sizes)
    EXPECT_NEAR(s, 0.1, 1e-12);
}

TEST(GradedBox, CoreCoveringTheBoxIsUniform)
{
  const auto sizes = shard::mesh::graded_cell_sizes(0., 0.178, 0., 0.178, 0.006, 1.2);
  ASSERT_EQ(sizes.size(), 30u);
  for (const double s : sizes)
    EXPECT_NEAR(s, 0.178 / 30, 1e-12);
}

// Boxes and rods go straight into rank 0's cell list, without a Triangulation (2026-12-07,
// doc/manual/cluster.md "The distributed mesh"). Their vertices (positions and numbering), cells
// and face ids must be those deal.II's GridGenerator::subdivided_hyper_rectangle (colorized)
// makes, bit for bit, so that results did not change: a graded box and a rod along y, off the
// origin, in one model.
TEST(BoxMesh, IsDealIIsSubdividedHyperRectangleBitForBit)
{
  using namespace dealii;
  const shard::base::PrmSource source = shard::test_support::scene_source(
    "shard_box_mesh_test.prm",
    "subsection B - Mesh\n set body names = slab, bar\n"
    " subsection slab\n  set shape = box\n  set lower corner = -0.05, -0.04, -0.03\n"
    "  set upper corner = 0.05, 0.04, 0.0\n  set element size = 0.01\n  set grading = 1.3\n"
    "  set fine lower corner = -0.02, -0.01, -0.03\n  set fine upper corner = 0.01, 0.01, -0.01\n"
    "  set material = steel\n end\n"
    " subsection bar\n  set shape = rod\n  set axis = y\n  set origin = 0.1, 0.2, 0.3\n"
    "  set length = 0.05\n  set width = 0.01\n  set element size = 0.004\n  set material = steel\n end\n"
    "end\n" +
      shard::test_support::elastic_steel());
  shard::mesh::Discretization       discretization{MPI_COMM_SELF};
  shard::materials::MaterialLibrary library;
  ParameterHandler                  prm;
  shard::base::read_parameters(prm, {&discretization, &library}, source);
  discretization.prepare(source);

  // The reference: deal.II's meshes of the two bodies, merged as shard merged them before (the
  // vertices of each body numbered in order of first use over its cells).
  std::vector<Point<3>>                                   position;
  std::vector<std::array<std::uint64_t, 8>>               cell_vertices;
  std::vector<std::array<types::boundary_id, 6>>          face_ids;
  const auto merge = [&](const Triangulation<3> &tria, const std::function<Point<3>(const Point<3> &)> &map) {
    std::map<unsigned int, std::uint64_t> number;
    for (const auto &cell : tria.active_cell_iterators())
      {
        std::array<std::uint64_t, 8> keys;
        for (unsigned int v = 0; v < 8; ++v)
          {
            const auto [it, inserted] = number.emplace(cell->vertex_index(v), position.size());
            if (inserted)
              position.push_back(map(cell->vertex(v)));
            keys[v] = it->second;
          }
        cell_vertices.push_back(keys);
        std::array<types::boundary_id, 6> ids;
        for (unsigned int f = 0; f < 6; ++f)
          ids[f] = cell->face(f)->at_boundary() ? cell->face(f)->boundary_id() : numbers::internal_face_boundary_id;
        face_ids.push_back(ids);
      }
  };
  {
    Triangulation<3>                 slab;
    std::vector<std::vector<double>> steps(3);
    const double low[3] = {-0.05, -0.04, -0.03}, high[3] = {0.05, 0.04, 0.0}, fl[3] = {-0.02, -0.01, -0.03},
                 fu[3] = {0.01, 0.01, -0.01};
    for (unsigned int d = 0; d < 3; ++d)
      steps[d] = shard::mesh::graded_cell_sizes(low[d], high[d], fl[d], fu[d], 0.01, 1.3);
    GridGenerator::subdivided_hyper_rectangle(slab, steps, Point<3>(low[0], low[1], low[2]),
                                              Point<3>(high[0], high[1], high[2]), true);
    merge(slab, [](const Point<3> &p) { return p; });
    Triangulation<3> bar;
    GridGenerator::subdivided_hyper_rectangle(bar, {13, 3, 3}, Point<3>(0, -0.005, -0.005), Point<3>(0.05, 0.005, 0.005),
                                              true);
    merge(bar, [](const Point<3> &p) { return Point<3>(p[2] + 0.1, p[0] + 0.2, p[1] + 0.3); });
  }

  ASSERT_EQ(discretization.triangulation().n_global_active_cells(), cell_vertices.size());
  ASSERT_EQ(discretization.n_global_vertices(), position.size());
  for (const auto &cell : discretization.triangulation().active_cell_iterators())
    {
      const auto c = cell->id().get_coarse_cell_id();
      ASSERT_LT(c, cell_vertices.size());
      for (unsigned int v = 0; v < 8; ++v)
        {
          const auto key = discretization.vertex_key(cell->vertex_index(v));
          ASSERT_EQ(key, cell_vertices[c][v]) << "cell " << c << " vertex " << v;
          for (unsigned int d = 0; d < 3; ++d)
            ASSERT_EQ(cell->vertex(v)[d], position[key][d]) << "cell " << c << " vertex " << v;
        }
      for (unsigned int f = 0; f < 6; ++f)
        ASSERT_EQ(cell->face(f)->at_boundary() ? cell->face(f)->boundary_id() : numbers::internal_face_boundary_id,
                  face_ids[c][f])
          << "cell " << c << " face " << f;
    }
}
