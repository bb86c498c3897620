// SPDX-License-Identifier: LGPL-2.1-or-later
/**
 * @file explicit_step.h
 * @brief The state the time loop advances and the phases of one explicit step.
 * @ingroup simulation
 */
#pragma once

#include <shard/base/keyed_records.h>
#include <shard/base/phase_timer.h>
#include <shard/base/traffic.h>
#include <shard/bc/boundary_conditions.h>
#include <shard/contact/contact.h>
#include <shard/coupling/conversion.h>
#include <shard/fe/hex_force.h>
#include <shard/mesh/discretization.h>
#include <shard/particles/bond_failure.h>
#include <shard/particles/particle_set.h>
#include <shard/particles/spg_force.h>
#include <shard/simulation/energy_balance.h>
#include <shard/time/central_difference.h>

#include <functional>
#include <string>
#include <vector>

namespace shard
{
  /**
   * @brief What the explicit step advances: the vectors (all with the one layout of the
   * Discretization) and the step clock. Each vector has one meaning at every point of the step.
   */
  struct StepState
  {
    /// Displacement d^n (particle coefficients at particles; owned and ghost entries).
    mesh::Vector d;
    /// Velocity v^{n+1/2} of the half step (after the kick: v^{n+3/2}).
    mesh::Vector v;
    /// Velocity v^n at the integer step (output, quantities, kinetic energy).
    mesh::Vector v_now;
    /// Total nodal force f^n of the last force evaluation: internal, contact and loads.
    mesh::Vector f;
    /// The loads (tractions, blast) at t^n.
    mesh::Vector f_ext;
    /// Lumped mass.
    mesh::Vector mass;
    /// Physical displacement u = A d at particles, d elsewhere (output; see Simulation).
    mesh::Vector d_phys;

    /// t^n (s).
    double t = 0;
    /// dt^{n-1/2}: the step just taken (s).
    double dt = 0;
    /// dt^{n+1/2}: the step the kick used, taken next (s).
    double dt_next = 0;
    /// The stable step of the last force evaluation, reduced over ranks after phase 8 (s).
    double stable_dt = 0;
    /// n.
    unsigned int step = 0;
    /// The global stable step before the first step: the reference of `minimum step fraction` (s).
    double first_stable_dt = 0;
    /// The particles' own step of the last force evaluation on this rank (s).
    double particle_dt = 1e300;

    /// Every vector, for (re)initialization and layout changes.
    std::vector<mesh::Vector *>
    vectors()
    {
      return {&d, &v, &v_now, &f, &f_ext, &mass, &d_phys};
    }

    /**
     * @brief The checkpoint of the owned nodes, by @p key_of(j) of the first local DOF j of a
     * node (a key independent of the partition): d, v, v_now, f, f_ext (15 values; the mass
     * and d_phys follow from the set-up and d).
     */
    base::KeyedRecords
    portable_state(const std::function<unsigned long long(unsigned int)> &key_of) const;

    /**
     * @brief Restart: every owned node takes what portable_state() wrote under its key, on
     * whichever rank that was (ghost values are not updated).
     * @throws std::runtime_error when a node is missing or has another number of values
     */
    void
    restore_portable(const base::KeyedLookup &saved, const std::function<unsigned long long(unsigned int)> &key_of);
  };

  /**
   * @brief The phases of one explicit step (doc/manual/time_loop.md), each one call and one
   * timer. Phase 10 (record) belongs to the Simulation that owns the output.
   *
   * Simulation::run() calls, per step: step_size(), drift(), exchange(), internal_forces(),
   * loads(), accumulate(), topology(), kick(). The step holds references to the components it
   * drives and to the StepState; it owns only the work counters (force evaluations and the
   * bytes sent at each exchange point) and the failure text of the step.
   */
  class ExplicitStep
  {
  public:
    /// The components a step drives (owned by Simulation).
    struct Components
    {
      mesh::Discretization     &discretization;
      particles::ParticleSet   &particles;
      particles::BondFailure   &bonds;
      coupling::Conversion     &conversion;
      contact::Contact         &contact;
      fe::HexForce             &hex;
      particles::SpgForce      &spg;
      bc::BoundaryConditions   &conditions;
      time::CentralDifference  &integrator;
      EnergyBalance            &energy;
      base::PhaseTimes         &times;
    };

    /**
     * @param convert converts the local elements it is given to particles (collective; phase
     *        4b): history transfer, particle set, stencils, ghost set, vectors moved to the new
     *        layout of @p state
     */
    ExplicitStep(MPI_Comm comm, const Components &components, StepState &state,
                 std::function<void(const std::vector<unsigned int> &)> convert);

    /// Phase 1: the step chosen at the end of the last step.
    void
    step_size();

    /// Phase 2: d += dt v on the owned entries; t += dt, n += 1.
    void
    drift();

    /// Phase 3: the only place ghost values are set (and the R1 filter on its steps).
    void
    exchange();

    /// Phases 5 and 6: FE and particle internal forces into f (a failure is kept for phase 8).
    void
    internal_forces();

    /// Phase 7: loads into f_ext, contact forces into f; the contact step limit.
    void
    loads();

    /**
     * @brief Phase 8: ghost force sums to their owners, f += f_ext, conversion candidates, one
     * reduction of the step, failure and conversion flags.
     * @throws Instability with the failure of any rank, or when the step collapsed below
     *         `minimum step fraction` of the first one. @note Collective.
     */
    void
    accumulate();

    /**
     * @brief Phase 4 after the force: conversion (4b, when a candidate exists) and bond
     * failure (4c, on check steps).
     * @return whether bonds broke or particles became free (the fragments changed)
     * @note Collective.
     */
    bool
    topology();

    /// Phase 9: v += (dt + dt_next)/2 a with the conditions; dt_next of the step after (the same on the @p last step).
    void
    kick(bool last);

    /// Element and particle force evaluations on this rank so far.
    double
    element_steps() const
    {
      return element_steps_;
    }

    /// Particle force evaluations on this rank so far.
    double
    particle_steps() const
    {
      return particle_steps_;
    }

    /// The bytes this rank sent at the exchange points since the start of this process.
    const base::Traffic &
    traffic() const
    {
      return traffic_;
    }

    /// Restart: the counters of a checkpoint.
    void
    restore_counters(const double element_steps, const double particle_steps)
    {
      element_steps_  = element_steps;
      particle_steps_ = particle_steps;
    }

    /// "; <condition>/function = ... is not finite: ..." for a non-finite load, or "". @note Collective.
    std::string
    non_finite_source() const;

    /// The diagnostic of a collapsed step (smallest element or particle step of all ranks). @note Collective.
    std::string
    collapsed_step_message() const;

  private:
    MPI_Comm                                               comm_;
    Components                                             c_;
    StepState                                             &s_;
    std::function<void(const std::vector<unsigned int> &)> convert_;
    double                                                 element_steps_ = 0, particle_steps_ = 0;
    base::Traffic                                          traffic_;
    /// Failure texts of this step's force evaluation on this rank ("" if none).
    std::string failure_;
    /// Elements of this rank that meet a conversion criterion, and whether any rank has one.
    std::vector<unsigned int> to_convert_;
    bool                      convert_now_ = false;
    /// Work space of the bond tests (failure values of the particles and their ghosts).
    mesh::Vector bond_values_;
    /// Change of the particle force when bonds break (phase 4c); allocated at the first break
    /// and again after a layout change, so that a run without breaks holds no such vector.
    mesh::Vector df_;
  };
} // namespace shard
