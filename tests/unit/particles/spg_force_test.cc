// SPDX-License-Identifier: LGPL-2.1-or-later
// SpgForce on a block of 5 x 5 x 5 particles (particles/spg_force.h) against closed forms: a
// uniform stretch gives the elastic stress at every particle, self-equilibrated forces and the
// virial sum_I f_I (x) X_I = -V0 P (linear exactness of A and of the corrected gradients); a
// rigid rotation gives no stress, no force and no work.
#include <shard/base/parameters.h>
#include <shard/materials/material_library.h>
#include <shard/mesh/discretization.h>
#include <shard/particles/particle_set.h>
#include <shard/particles/spg_force.h>

#include <support/scene_text.h>

#include <deal.II/base/parameter_handler.h>

#include <gtest/gtest.h>

#include <cmath>
#include <string>

namespace
{
  using namespace shard;

  struct Block
  {
    base::PrmSource            source;
    mesh::Discretization       discretization{MPI_COMM_SELF};
    materials::MaterialLibrary library;
    particles::ParticleSet     particles;
    particles::SpgForce        spg;
    dealii::ParameterHandler   prm;
    mesh::Vector               d, f;

    Block()
    {
      source = test_support::scene_source("shard_spg_force_test.prm",
                                          test_support::unit_cube(2) + test_support::elastic_steel() +
                                            "subsection E - Particles\n set bodies = cube\nend\n");
      base::read_parameters(prm, {&discretization, &library, &particles, &spg}, source);
      discretization.prepare(source);
      library.prepare();
      particles.prepare(discretization,
                        std::vector<bool>(discretization.triangulation().n_active_cells(), true), {}, source);
      spg.prepare(discretization, particles, library);
      discretization.initialize_vector(d);
      discretization.initialize_vector(f);
    }

    /// d = u(X) at every particle.
    template <typename U>
    void
    set(const U &u)
    {
      for (unsigned int i = 0; i < particles.n_owned(); ++i)
        for (unsigned int c = 0; c < 3; ++c)
          d.local_element(particles.local_dof(i) + c) = u(particles.position(i).data(), c);
      d.update_ghost_values();
    }

    particles::ParticleForceResult
    force(const double dt, const unsigned int step)
    {
      f = 0;
      const auto r = spg.add_internal_forces(d, dt, step, f);
      f.compress(dealii::VectorOperation::add);
      return r;
    }
  };

  const double E = 200e9, nu = 0.3, K = E / (3 * (1 - 2 * nu)), G = E / (2 * (1 + nu));
} // namespace

TEST(SpgForce, UniformStretchGivesTheElasticStressAndTheVirial)
{
  Block b;
  ASSERT_EQ(b.particles.n_owned(), 125u);
  const double eps = 1e-4;
  b.set([&](const double *x, unsigned int c) { return c == 0 ? eps * x[0] : 0.; });
  b.force(1e-7, 1);
  // F = diag(1 + eps, 1, 1) at every particle; dt L = (F - I) F_mid^-1, J = 1 + eps.
  const double de = eps / (1 + eps / 2), lnJ = std::log(1 + eps);
  const double sxx = K * lnJ + 2 * G * (2. / 3.) * de, syy = K * lnJ - 2 * G * (1. / 3.) * de;
  for (unsigned int i = 0; i < b.particles.n_owned(); ++i)
    {
      EXPECT_NEAR(b.spg.stress(i)[0], sxx, 1e-6 * sxx) << i;
      EXPECT_NEAR(b.spg.stress(i)[1], syy, 1e-6 * sxx) << i;
      EXPECT_NEAR(b.spg.stress(i)[5], 0., 1e-6 * sxx) << i;
    }
  // Forces: sum zero; virial sum_I f_I (x) X_I = -V0 P, P = J sigma F^-T (V0 = 1 m^3).
  double sum[3] = {0, 0, 0}, virial[3][3] = {};
  for (unsigned int i = 0; i < b.particles.n_owned(); ++i)
    for (unsigned int a = 0; a < 3; ++a)
      {
        const double fa = b.f.local_element(b.particles.local_dof(i) + a);
        sum[a] += fa;
        for (unsigned int c = 0; c < 3; ++c)
          virial[a][c] += fa * b.particles.position(i)[c];
      }
  for (unsigned int a = 0; a < 3; ++a)
    EXPECT_NEAR(sum[a], 0., 1e-9 * sxx);
  EXPECT_NEAR(virial[0][0], -sxx, 1e-6 * sxx);
  EXPECT_NEAR(virial[1][1], -(1 + eps) * syy, 1e-6 * sxx);
  EXPECT_NEAR(virial[2][2], -(1 + eps) * syy, 1e-6 * sxx);
  EXPECT_NEAR(virial[0][1], 0., 1e-6 * sxx);
}

TEST(SpgForce, RigidRotationGivesNoStressNoForceNoWork)
{
  Block        b;
  const double a = 0.3, ca = std::cos(a), sa = std::sin(a); // one step of a finite rotation
  b.set([&](const double *x, unsigned int c) {
    return c == 0 ? ca * x[0] - sa * x[1] - x[0] : c == 1 ? sa * x[0] + ca * x[1] - x[1] : 0.;
  });
  const auto r = b.force(1e-7, 1);
  // F = R: (F - I) ((F + I) / 2)^-1 is skew (a Cayley transform), so no strain and no stress.
  double largest = 0;
  for (unsigned int i = 0; i < b.particles.n_owned(); ++i)
    for (unsigned int k = 0; k < 6; ++k)
      largest = std::max(largest, std::abs(b.spg.stress(i)[k]));
  const double scale = E * 1e-12; // round-off of a unit rotation
  EXPECT_LT(largest, 1e3 * scale);
  double force = 0;
  for (unsigned int i = 0; i < b.particles.n_owned(); ++i)
    for (unsigned int c = 0; c < 3; ++c)
      force = std::max(force, std::abs(b.f.local_element(b.particles.local_dof(i) + c)));
  EXPECT_LT(force, 1e3 * scale);
  EXPECT_LT(std::abs(r.internal_energy), 1e3 * scale * 1e-12);
}
