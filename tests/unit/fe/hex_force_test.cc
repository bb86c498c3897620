// SPDX-License-Identifier: LGPL-2.1-or-later
// HexForce on one element (fe/hex_force.h) against closed forms: a uniaxial stretch gives the
// elastic stress and the nodal forces sigma A / 4 on the stretched faces; a rigid rotation of
// the stressed element rotates the stress (objective update) and does no work; a compressing
// step gives the bulk-viscosity pressure and its step limit.
#include <shard/base/parameters.h>
#include <shard/fe/hex_force.h>
#include <shard/materials/material_library.h>
#include <shard/mesh/discretization.h>

#include <support/scene_text.h>

#include <deal.II/base/parameter_handler.h>

#include <gtest/gtest.h>

#include <cmath>
#include <string>

namespace
{
  using namespace shard;

  /// One unit-cube element of elastic steel (E 200 GPa, nu 0.3), bulk viscosity as given.
  struct OneElement
  {
    base::PrmSource            source;
    mesh::Discretization       discretization{MPI_COMM_SELF};
    materials::MaterialLibrary library;
    fe::HexForce               hex;
    dealii::ParameterHandler   prm;
    mesh::Vector               d, v, f;

    explicit OneElement(const std::string &viscosity = "set bulk viscosity linear = 0\nset bulk viscosity quadratic = 0\n")
    {
      source = test_support::scene_source("shard_hex_force_test.prm",
                                          test_support::unit_cube(0) + test_support::elastic_steel() +
                                            "subsection D - Finite elements\n" + viscosity + "end\n");
      base::read_parameters(prm, {&discretization, &library, &hex}, source);
      discretization.prepare(source);
      library.prepare();
      hex.prepare(discretization, library, {});
      for (auto *x : {&d, &v, &f})
        discretization.initialize_vector(*x);
    }

    /// Sets d = u(X) and v = w(X) at every node.
    template <typename U, typename W>
    void
    set(const U &u, const W &w)
    {
      const auto &X = discretization.reference_positions();
      for (unsigned int j = 0; j < X.locally_owned_size(); j += 3)
        {
          const double x[3] = {X.local_element(j), X.local_element(j + 1), X.local_element(j + 2)};
          for (unsigned int c = 0; c < 3; ++c)
            {
              d.local_element(j + c) = u(x, c);
              v.local_element(j + c) = w(x, c);
            }
        }
    }

    fe::ForceResult
    force(const double dt, const unsigned int step = 1)
    {
      f = 0;
      const auto r = hex.add_internal_forces(d, v, dt, step, f);
      f.compress(dealii::VectorOperation::add);
      return r;
    }
  };

  const double E = 200e9, nu = 0.3, K = E / (3 * (1 - 2 * nu)), G = E / (2 * (1 + nu));
} // namespace

TEST(HexForce, UniaxialStretchGivesTheElasticStressAndFaceForces)
{
  OneElement   one;
  const double eps = 1e-4, dt = 1e-7;
  // One step from rest to x = (1 + eps) X, with v = eps X / dt over the step.
  one.set([&](const double *x, unsigned int c) { return c == 0 ? eps * x[0] : 0.; },
          [&](const double *x, unsigned int c) { return c == 0 ? eps * x[0] / dt : 0.; });
  const auto r = one.force(dt);
  ASSERT_EQ(one.hex.n_local_elements(), 1u);
  // Strain increment dt L = ln-rate over the step: de_xx = eps / (1 + eps / 2) (mid-point
  // gradient), J = 1 + eps; the elastic model: sigma = K ln J I + 2G dev(de).
  const double de = eps / (1 + eps / 2), lnJ = std::log(1 + eps);
  const double sxx = K * lnJ + 2 * G * (2. / 3.) * de, syy = K * lnJ - 2 * G * (1. / 3.) * de;
  EXPECT_NEAR(one.hex.stress(0)[0], sxx, 1e-9 * sxx);
  EXPECT_NEAR(one.hex.stress(0)[1], syy, 1e-9 * sxx);
  EXPECT_NEAR(one.hex.stress(0)[3], 0., 1e-9 * sxx);
  // Nodal forces: -sigma_xx A / 4 at each node of the face x = 1 + eps (area 1), +sigma_xx A / 4
  // at x = 0; the y and z forces are -+ sigma_yy (1 + eps) / 4 on their faces.
  const auto &X = one.discretization.reference_positions();
  double      sum[3] = {0, 0, 0};
  for (unsigned int j = 0; j < X.locally_owned_size(); j += 3)
    {
      const double fx = one.f.local_element(j), fy = one.f.local_element(j + 1);
      EXPECT_NEAR(fx, (X.local_element(j) > 0.5 ? -1 : 1) * sxx / 4, 1e-9 * sxx);
      EXPECT_NEAR(fy, (X.local_element(j + 1) > 0.5 ? -1 : 1) * syy * (1 + eps) / 4, 1e-9 * sxx);
      for (unsigned int c = 0; c < 3; ++c)
        sum[c] += one.f.local_element(j + c);
    }
  for (unsigned int c = 0; c < 3; ++c)
    EXPECT_NEAR(sum[c], 0., 1e-9 * sxx); // internal forces are self-equilibrated
  // Stress work of the step: V_mid (0 + sigma) : de / 2.
  EXPECT_NEAR(r.internal_energy, 0.5 * (1 + eps / 2) * (sxx * de), 1e-6 * sxx * de);
  // Step: L / c with L = V / A_max = 1 (the x faces keep their area) and the dilatational
  // wave speed (of the initial or the current density: they differ by 5e-5 here).
  const double c = std::sqrt((K + 4 * G / 3) / 7850);
  EXPECT_NEAR(r.stable_dt, 1 / c, 1e-4 / c);
}

TEST(HexForce, RigidRotationRotatesTheStressAndDoesNoWork)
{
  OneElement   one;
  const double eps = 1e-4, dt = 1e-7;
  one.set([&](const double *x, unsigned int c) { return c == 0 ? eps * x[0] : 0.; },
          [&](const double *x, unsigned int c) { return c == 0 ? eps * x[0] / dt : 0.; });
  one.force(dt);
  const double s0[6] = {one.hex.stress(0)[0], one.hex.stress(0)[1], one.hex.stress(0)[2],
                        one.hex.stress(0)[3], one.hex.stress(0)[4], one.hex.stress(0)[5]};
  // Rotate the stretched cube about z by 0.5 rad in 500 steps: x = R(t) (1 + eps e_x e_x) X,
  // v = w x (x - centre is not needed: a rigid spin about the origin).
  const unsigned int n = 500;
  const double       omega = 0.5 / (n * dt);
  double             work  = 0;
  for (unsigned int k = 1; k <= n; ++k)
    {
      const double a = omega * k * dt, ca = std::cos(a), sa = std::sin(a);
      one.set(
        [&](const double *x, unsigned int c) {
          const double y0 = (1 + eps) * x[0], y1 = x[1];
          return c == 0 ? ca * y0 - sa * y1 - x[0] : c == 1 ? sa * y0 + ca * y1 - x[1] : 0.;
        },
        [&](const double *x, unsigned int c) {
          // the spin at mid-step: velocity of the mid-step configuration
          const double am = a - 0.5 * omega * dt, cm = std::cos(am), sm = std::sin(am);
          const double y0 = (1 + eps) * x[0], y1 = x[1];
          return c == 0 ? -omega * (sm * y0 + cm * y1) : c == 1 ? omega * (cm * y0 - sm * y1) : 0.;
        });
      work += one.force(dt, k + 1).internal_energy;
    }
  // sigma' = R sigma R^T about z by 0.5 rad.
  const double a = 0.5, ca = std::cos(a), sa = std::sin(a);
  const double xx = ca * ca * s0[0] + sa * sa * s0[1], yy = sa * sa * s0[0] + ca * ca * s0[1];
  const double xy = ca * sa * (s0[0] - s0[1]);
  EXPECT_NEAR(one.hex.stress(0)[0], xx, 1e-5 * s0[0]);
  EXPECT_NEAR(one.hex.stress(0)[1], yy, 1e-5 * s0[0]);
  EXPECT_NEAR(one.hex.stress(0)[5], xy, 1e-5 * s0[0]);
  EXPECT_NEAR(one.hex.stress(0)[2], s0[2], 1e-6 * s0[0]);
  // No stretching: the stress work of the whole rotation is round-off of the stored energy.
  EXPECT_LT(std::abs(work), 1e-6 * 0.5 * s0[0] * eps);
}

TEST(HexForce, CompressionGivesTheBulkViscosityAndItsStepLimit)
{
  OneElement   one("set bulk viscosity linear = 0.06\nset bulk viscosity quadratic = 1.5\n");
  const double eps = -1e-3, dt = 1e-7; // volumetric compression in one step
  one.set([&](const double *x, unsigned int c) { return eps * x[c]; },
          [&](const double *x, unsigned int c) { return eps * x[c] / dt; });
  const auto r = one.force(dt);
  // Without viscosity the same step gives sigma = K ln J I; with it the nodal forces carry
  // sigma - q I, and the step is L / (c (sqrt(1 + r^2) + r)), r = Q1 - Q2 L tr(de) / (dt c).
  OneElement plain;
  plain.set([&](const double *x, unsigned int c) { return eps * x[c]; },
            [&](const double *x, unsigned int c) { return eps * x[c] / dt; });
  const auto   r0  = plain.force(dt);
  const double J   = std::pow(1 + eps, 3), L = (1 + eps), rho = 7850 / J;
  const double trd = 3 * eps / (1 + eps / 2);
  const double c   = L / r0.stable_dt; // the wave speed the material returned (no viscosity: L / c)
  const double q   = rho * L * (1.5 * L * (trd / dt) * (trd / dt) - 0.06 * c * trd / dt);
  // Face force difference: q A / 4 per node, outward of the compressed element: the viscous
  // pressure pushes the faces apart.
  const double area = L * L;
  EXPECT_NEAR(one.f.local_element(0) - plain.f.local_element(0), -q * area / 4, 1e-6 * q * area);
  const double rr = 0.06 - 1.5 * L * trd / dt / c;
  EXPECT_NEAR(r.stable_dt, L / (c * (std::sqrt(1 + rr * rr) + rr)), 1e-6 * r.stable_dt);
  EXPECT_LT(r.stable_dt, r0.stable_dt);
  // Its work is dissipated: more internal energy than the elastic step.
  EXPECT_GT(r.internal_energy, r0.internal_energy);
}
