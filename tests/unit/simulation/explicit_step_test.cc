// SPDX-License-Identifier: LGPL-2.1-or-later
// The phases of ExplicitStep (simulation/explicit_step.h) on one elastic hexahedron, against
// closed forms: a rigid translation drifts exactly and makes no force; the breathing mode of
// the element (uniform dilatation) follows the discrete central-difference solution of its
// linear oscillator, with the energy balance closed.
#include <shard/base/parameters.h>
#include <shard/base/phase_timer.h>
#include <shard/bc/boundary_conditions.h>
#include <shard/contact/contact.h>
#include <shard/coupling/conversion.h>
#include <shard/fe/hex_force.h>
#include <shard/materials/material_library.h>
#include <shard/mesh/discretization.h>
#include <shard/particles/bond_failure.h>
#include <shard/particles/particle_set.h>
#include <shard/particles/spg_force.h>
#include <shard/simulation/energy_balance.h>
#include <shard/simulation/explicit_step.h>
#include <shard/time/central_difference.h>

#include <support/scene_text.h>

#include <deal.II/base/parameter_handler.h>

#include <gtest/gtest.h>

#include <cmath>
#include <iomanip>
#include <sstream>
#include <string>

namespace
{
  using namespace shard;

  constexpr double E = 200e9, nu = 0.3, rho = 7850, K = E / (3 * (1 - 2 * nu));

  /// One unit-cube element of elastic steel without bulk viscosity, every component of the step
  /// set up as Simulation::prepare() does, the step fixed at @p dt.
  struct OneElementStep
  {
    base::PrmSource            source;
    dealii::ParameterHandler   prm;
    mesh::Discretization       discretization{MPI_COMM_SELF};
    materials::MaterialLibrary materials;
    particles::ParticleSet     particles;
    particles::BondFailure     bonds{materials};
    coupling::Conversion       conversion;
    contact::Contact           contact;
    fe::HexForce               hex;
    particles::SpgForce        spg;
    bc::BoundaryConditions     conditions;
    time::CentralDifference    integrator;
    EnergyBalance              energy;
    base::PhaseTimes           times;
    StepState                  state;
    ExplicitStep               step{MPI_COMM_SELF,
                      {discretization, particles, bonds, conversion, contact, hex, spg, conditions, integrator, energy,
                       times},
                      state, [](const std::vector<unsigned int> &) { FAIL() << "no conversion expected"; }};

    explicit OneElementStep(const double dt)
    {
      std::ostringstream step;
      step << std::setprecision(17) << dt;
      source = test_support::scene_source("shard_explicit_step_test.prm",
                                          test_support::unit_cube(0) + test_support::elastic_steel() +
                                            "subsection D - Finite elements\n set bulk viscosity linear = 0\n"
                                            " set bulk viscosity quadratic = 0\nend\n"
                                            "subsection J - Time integration\n set end time = 1\n"
                                            " set fixed time step = " + step.str() + "\nend\n");
      base::read_parameters(prm,
                            {&discretization, &materials, &particles, &bonds, &conversion, &contact, &hex, &spg,
                             &conditions, &integrator},
                            source);
      discretization.prepare(source);
      materials.prepare();
      conversion.prepare(discretization, particles.body_names(), source);
      particles.prepare(discretization, conversion.converted_cells(), conditions.faces(), source);
      hex.prepare(discretization, materials, conversion.converted_cells());
      spg.prepare(discretization, particles, materials);
      bonds.prepare(particles, spg, source);
      conditions.prepare(discretization, source);
      for (auto *vec : state.vectors())
        discretization.initialize_vector(*vec);
      hex.add_lumped_mass(state.mass);
      state.mass.compress(dealii::VectorOperation::add);
      state.mass.update_ghost_values();
      contact.prepare(discretization, materials, particles, conversion.converted_cells(), state.mass, source);
      integrator.rigid_bodies().prepare(discretization, materials, state.mass);
    }

    /// Sets the initial velocity v = w(X) and takes the initial half kick (Simulation::start()).
    template <typename W>
    void
    start(const W &w)
    {
      const auto &X  = discretization.reference_positions();
      double      ke = 0;
      for (unsigned int j = 0; j < X.locally_owned_size(); j += 3)
        {
          const double x[3] = {X.local_element(j), X.local_element(j + 1), X.local_element(j + 2)};
          for (unsigned int c = 0; c < 3; ++c)
            {
              state.v.local_element(j + c) = w(x, c);
              ke += 0.5 * state.mass.local_element(j + c) * w(x, c) * w(x, c);
            }
        }
      energy.set_initial_kinetic(ke);
      state.stable_dt       = hex.initial_stable_dt();
      state.first_stable_dt = state.stable_dt;
      state.f               = 0;
      state.f_ext           = 0;
      state.dt_next         = integrator.next_dt(state.stable_dt, 0.);
      integrator.kick(0., 0., state.dt_next, state.f, state.f_ext, state.mass, state.d, conditions, state.v,
                      state.v_now, energy.kick_terms());
      state.d.update_ghost_values();
      state.v_now.update_ghost_values();
    }

    /// One step, the phases in the order of Simulation::run().
    void
    advance()
    {
      step.step_size();
      step.drift();
      step.exchange();
      step.internal_forces();
      step.loads();
      step.accumulate();
      ASSERT_FALSE(step.topology());
      step.kick(false);
    }
  };
} // namespace

// Rigid translation at v0: drift moves every node by dt v0 per step, the element makes no force,
// the kinetic energy and the momentum stay those of the input, and nothing else is booked.
TEST(ExplicitStep, RigidTranslationDriftsExactlyAndMakesNoForce)
{
  const double   dt = 1e-7;
  OneElementStep one(dt);
  const double   v0[3] = {3., -2., 0.5};
  one.start([&](const double *, const unsigned int c) { return v0[c]; });
  EXPECT_EQ(one.state.dt_next, dt);
  const unsigned int n = 50;
  for (unsigned int k = 0; k < n; ++k)
    one.advance();
  EXPECT_EQ(one.state.step, n);
  EXPECT_NEAR(one.state.t, n * dt, 1e-15 * n * dt);
  const auto &d = one.state.d;
  for (unsigned int j = 0; j < d.locally_owned_size(); ++j)
    {
      EXPECT_NEAR(d.local_element(j), v0[j % 3] * n * dt, 1e-12 * n * dt);
      EXPECT_NEAR(one.state.f.local_element(j), 0., 1e-3); // round-off of 1e11 Pa moduli
      EXPECT_NEAR(one.state.v_now.local_element(j), v0[j % 3], 1e-9);
    }
  const auto totals = one.energy.reduce({}, MPI_COMM_SELF);
  const double mass = rho * 1.;
  EXPECT_NEAR(totals.kinetic, 0.5 * mass * (9. + 4. + 0.25), 1e-9 * mass);
  EXPECT_NEAR(totals.momentum[0], mass * v0[0], 1e-9 * mass);
  EXPECT_NEAR(totals.momentum[1], mass * v0[1], 1e-9 * mass);
  EXPECT_LT(std::abs(totals.internal), 1e-9 * mass);
  EXPECT_LT(std::abs(one.energy.error()), 1e-9);
}

// Breathing mode: v = r (X - c) about the centre c is a uniform dilatation. The corner of mass
// rho / 8 moves u = eps / 2 along each axis, the pressure K ln J ~ 3 K eps pushes each face node
// with 3 K eps / 4 = 1.5 K u: a linear oscillator of omega^2 = 12 K / rho (no shear, no
// hourglass). Central differences with a fixed step solve it as u_n = C sin(n theta),
// cos(theta) = 1 - (omega dt)^2 / 2, C = dt v_0 / sin(theta) (u_0 = 0, v^{1/2} = v_0). The
// amplitude is 1e-7 of the edge, so the geometric nonlinearity is below 1e-6 of it.
TEST(ExplicitStep, BreathingModeFollowsTheDiscreteOscillator)
{
  const double omega = std::sqrt(12 * K / rho);
  const double dt    = 0.2 / omega; // about 1/31 of the period; the element's own limit is 0.31 / omega
  OneElementStep one(dt);
  const double   amplitude = 1e-7, v0 = amplitude * omega; // corner speed along each axis
  const double   r         = 2 * v0;
  one.start([&](const double *x, const unsigned int c) { return r * (x[c] - 0.5); });
  ASSERT_EQ(one.state.dt_next, dt);
  const double theta = std::acos(1 - 0.5 * omega * dt * omega * dt);
  const double C     = dt * v0 / std::sin(theta);
  const auto  &X     = one.discretization.reference_positions();
  double       largest_error = 0, largest = 0;
  for (unsigned int n = 1; n <= 200; ++n)
    {
      one.advance();
      const double u = C * std::sin(n * theta);
      for (unsigned int j = 0; j < X.locally_owned_size(); ++j)
        {
          const double sign = X.local_element(j) > 0.5 ? 1. : -1.;
          largest_error     = std::max(largest_error, std::abs(one.state.d.local_element(j) - sign * u));
          largest           = std::max(largest, std::abs(one.state.d.local_element(j)));
        }
    }
  // Measured: largest within 9e-6 C (the sampled peak), error 4e-7 C (the nonlinearity, eps
  // = 2e-7), energy error 4.8e-9.
  EXPECT_NEAR(largest, C, 1e-4 * C);
  EXPECT_LT(largest_error, 2e-6 * C);
  // The energy balance closes: stress work against the kinetic energy the mode gave up.
  const auto totals = one.energy.reduce({}, MPI_COMM_SELF);
  EXPECT_GT(totals.internal, 0.);
  EXPECT_LT(std::abs(one.energy.max_error()), 1e-6);
}
