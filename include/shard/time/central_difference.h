// SPDX-License-Identifier: LGPL-2.1-or-later
/**
 * @file central_difference.h
 * @brief Central-difference (kick-drift) time integration and the stable step
 *        (subsection `J - Time integration`).
 * @ingroup time
 */
#pragma once

#include <shard/base/parameters.h>
#include <shard/bc/boundary_conditions.h>
#include <shard/mesh/discretization.h>
#include <shard/time/rigid_bodies.h>

namespace shard::time
{
  /// Energy terms and momentum of this rank, summed over ranks at output rows.
  struct LocalBalance
  {
    /// Kinetic energy at the current integer step (J).
    double kinetic = 0;
    /// Linear momentum at the current integer step (kg m/s).
    double momentum[3] = {0, 0, 0};
    /// Work of the traction forces up to the current step (J).
    double external_work = 0;
    /// Work of the reaction forces of kinematic conditions up to the current step (J).
    double boundary_work = 0;
    /// Second half of the last kick's work, which belongs to the next step.
    double pending_external = 0, pending_boundary = 0;
  };

  /**
   * @brief Central difference with variable step:
   * @f$ v^{n+1/2} = v^{n-1/2} + \tfrac12(\Delta t^{n-1/2} + \Delta t^{n+1/2}) a^n @f$,
   * @f$ d^{n+1} = d^n + \Delta t^{n+1/2} v^{n+1/2} @f$.
   *
   * The kick follows the force evaluation of the same step, so that kinematic constraints,
   * their reactions and the integer-step kinetic energy are known when the step is recorded.
   */
  class CentralDifference : public base::ParameterOwner
  {
  public:
    bool
    declare_parameters(dealii::ParameterHandler &prm) override;

    void
    check_parameters(const base::PrmSource &source) const override;

    /// End time (s).
    double
    end_time() const
    {
      return end_time_;
    }

    /// Fixed step (s); 0: the stable step.
    double
    fixed_time_step() const
    {
      return fixed_dt_;
    }

    /// Largest number of steps (0: no limit).
    unsigned int
    max_steps() const
    {
      return max_steps_;
    }

    /// Relative energy error above which the run stops as unstable.
    double
    energy_error_limit() const
    {
      return energy_error_limit_;
    }

    /// Fraction of the first stable step below which the run stops as unstable (0: never).
    double
    minimum_step_fraction() const
    {
      return min_step_fraction_;
    }

    /// Safety factor applied to the stable step.
    double
    safety_factor() const
    {
      return safety_factor_;
    }

    /**
     * @brief Size of the next step at time @p t: the fixed step if one is set, otherwise the
     * held step, kept while it lies in [(1 - b), 1] times the safety factor times
     * @p stable_dt and reset to that bound when it leaves (b the step size band); never past
     * the end time.
     */
    double
    next_dt(double stable_dt, double t);

    /// d += dt v on owned entries (rigid bodies: their exact rotation; their v turns with them).
    void
    drift(double dt, mesh::Vector &v, mesh::Vector &d);

    /**
     * @brief The kick at time @p t: unconstrained update with a = f / m, the rigid-body
     * projection (RigidBodies::project), kinematic conditions,
     * integer-step kinetic energy and momentum, work of tractions and reactions.
     *
     * @param[in] dt_old the step just taken (0 at the start)
     * @param[in] dt_new the next step
     * @param[in] f total force (internal + external), owned entries final
     * @param[in] f_ext traction forces alone, for their work
     * @param[in,out] v half-step velocity: v^{n-1/2} in, v^{n+1/2} out
     * @param[out] v_now integer-step velocity v^n (owned entries)
     * @param[in,out] balance energy terms of this rank
     */
    void
    kick(double t, double dt_old, double dt_new, const mesh::Vector &f, const mesh::Vector &f_ext,
         const mesh::Vector &mass, const mesh::Vector &d, bc::BoundaryConditions &conditions, mesh::Vector &v,
         mesh::Vector &v_now, LocalBalance &balance);

    /// The rigid bodies whose nodes the kick moves as one (prepare them before the first kick).
    RigidBodies &
    rigid_bodies()
    {
      return rigid_;
    }

    /// The held step (s): the only state the integrator carries from step to step (checkpoint).
    double
    held_dt() const
    {
      return held_dt_;
    }

    /// Restores the held step of a checkpoint.
    void
    set_held_dt(const double dt)
    {
      held_dt_ = dt;
    }

  private:
    RigidBodies  rigid_;
    double       end_time_           = 1e-4;
    double       safety_factor_      = 0.9;
    double       fixed_dt_           = 0.;
    double       step_band_          = 0.05;
    double       held_dt_            = 0.;
    unsigned int max_steps_          = 0;
    double       energy_error_limit_ = 0.1;
    double       min_step_fraction_  = 0.01;
    mesh::Vector acceleration_, v_old_;
  };
} // namespace shard::time
