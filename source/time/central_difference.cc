// SPDX-License-Identifier: LGPL-2.1-or-later
#include <shard/time/central_difference.h>

#include <algorithm>

namespace shard::time
{
  using namespace dealii;

  bool
  CentralDifference::declare_parameters(ParameterHandler &prm)
  {
    if (declared_)
      return false;
    declared_ = true;
    prm.enter_subsection("J - Time integration");
    prm.add_parameter("end time", end_time_, "Simulated end time. Unit: s. Range: > 0.", Patterns::Double(0));
    prm.add_parameter("safety factor", safety_factor_,
                      "Factor on the smallest element step L_e / c_e (LS-DYNA TSSFAC). Unit: 1. Range: (0, 1].",
                      Patterns::Double(0, 1));
    prm.add_parameter("fixed time step", fixed_dt_,
                      "A fixed step instead of the stable one (tests); 0 uses the stable step. Unit: s. Range: >= 0.",
                      Patterns::Double(0));
    prm.add_parameter("step size band", step_band_,
                      "Hysteresis of the step: the step is held while it lies between (1 - b) and 1 times the "
                      "safety factor times the stable step, and reset to that bound when it leaves the band, so a "
                      "bound that oscillates settles the step on its minimum. A step that follows every small change "
                      "of the bound (b = 0) pumps energy into a vibrating body (the central difference with varying "
                      "steps is not symplectic; doc/decisions/0005-step-size-band.md). Unit: 1. Range: 0 to 0.2.",
                      Patterns::Double(0, 0.2));
    prm.add_parameter("max steps", max_steps_, "Stop after this many steps; 0: no limit. Unit: 1.",
                      Patterns::Integer(0));
    prm.add_parameter("minimum step fraction", min_step_fraction_,
                      "The run stops as unstable when the stable step falls below this fraction of the first "
                      "step (like LS-DYNA's DTMIN): a collapsing step is how a lattice that turns unstable "
                      "without an energy error shows itself. The message names the element or particle with "
                      "the smallest step. 0: no such stop. Unit: 1. Range: 0 to 1.",
                      Patterns::Double(0, 1));
    prm.add_parameter("energy error limit", energy_error_limit_,
                      "The run stops as unstable when |energy error| exceeds this fraction of the reference "
                      "energy. Unit: 1. Range: > 0.",
                      Patterns::Double(0));
    prm.leave_subsection();
    return true;
  }

  void
  CentralDifference::check_parameters(const base::PrmSource &source) const
  {
    const std::string p = "J - Time integration/";
    if (!(end_time_ > 0))
      source.fail(p + "end time", std::to_string(end_time_), "must be > 0. Unit: s.");
    if (!(safety_factor_ > 0 && safety_factor_ <= 1))
      source.fail(p + "safety factor", std::to_string(safety_factor_), "must be in (0, 1]. Unit: 1.");
    if (!(step_band_ >= 0 && step_band_ <= 0.2))
      source.fail(p + "step size band", std::to_string(step_band_), "must be in [0, 0.2]. Unit: 1.");
    if (!(energy_error_limit_ > 0))
      source.fail(p + "energy error limit", std::to_string(energy_error_limit_), "must be > 0. Unit: 1.");
  }

  double
  CentralDifference::next_dt(const double stable_dt, const double t)
  {
    const double bound = safety_factor_ * stable_dt;
    if (!(held_dt_ <= bound && held_dt_ >= (1 - step_band_) * bound))
      held_dt_ = bound;
    const double dt        = fixed_dt_ > 0 ? fixed_dt_ : held_dt_;
    const double remaining = end_time_ - t;
    // Avoid a sliver of a last step: stretch or split the remainder evenly.
    if (remaining <= dt * (1 + 1e-9))
      return remaining;
    if (remaining < 2 * dt)
      return 0.5 * remaining;
    return dt;
  }

  void
  CentralDifference::drift(const double dt, const mesh::Vector &v, mesh::Vector &d) const
  {
    const unsigned int n  = d.locally_owned_size();
    double            *dp = d.begin();
    const double      *vp = v.begin();
    for (unsigned int i = 0; i < n; ++i)
      dp[i] += dt * vp[i];
  }

  void
  CentralDifference::kick(const double t, const double dt_old, const double dt_new, const mesh::Vector &f,
                          const mesh::Vector &f_ext, const mesh::Vector &mass, const mesh::Vector &d,
                          bc::BoundaryConditions &conditions, mesh::Vector &v, mesh::Vector &v_now,
                          LocalBalance &balance)
  {
    if (acceleration_.size() != v.size() || acceleration_.get_partitioner() != v.get_partitioner())
      {
        acceleration_.reinit(v);
        v_old_.reinit(v);
      }
    const unsigned int n      = v.locally_owned_size();
    const double       dt_avg = 0.5 * (dt_old + dt_new);
    const double *fp = f.begin(), *mp = mass.begin();
    double       *ap = acceleration_.begin(), *vp = v.begin(), *op = v_old_.begin();
    for (unsigned int i = 0; i < n; ++i)
      {
        ap[i] = fp[i] / mp[i];
        op[i] = vp[i];
        vp[i] += dt_avg * ap[i];
      }
    const auto [bc_before, bc_after] =
      conditions.apply_kinematic(t + 0.5 * dt_new, dt_avg, dt_new, dt_old, d, mass, acceleration_, v);

    // Work up to step n: the pending second half of the last kick plus the first half of this one.
    const double *ep  = f_ext.begin();
    double       *vn  = v_now.begin();
    double        ext_before = 0, ext_after = 0, kinetic = 0, p[3] = {0, 0, 0};
    const double  w   = dt_avg > 0 ? 0.5 * dt_old / dt_avg : 0.;
    for (unsigned int i = 0; i < n; ++i)
      {
        // v^n = v^{n-1/2} + dt_old / 2 a_eff with the constrained a_eff = (v^{n+1/2} - v^{n-1/2}) / dt_avg.
        vn[i] = op[i] + w * (vp[i] - op[i]);
        // Kinetic energy in the product form m v^{n-1/2} v^{n+1/2}: with the trapezoidal work of the
        // internal forces it makes the energy of a linear system exactly conserved by the
        // central difference at any frequency, whereas m (v^n)^2 is off by (omega dt)^2 / 8
        // in every mode near the stability limit (doc/decisions/0004-kinetic-energy.md).
        kinetic += mp[i] * op[i] * vp[i];
        p[i % 3] += mp[i] * vn[i];
        ext_before += ep[i] * 0.5 * dt_old * op[i];
        ext_after += ep[i] * 0.5 * dt_new * vp[i];
      }
    balance.kinetic = 0.5 * kinetic;
    for (unsigned int i = 0; i < 3; ++i)
      balance.momentum[i] = p[i];
    balance.external_work += balance.pending_external + ext_before;
    balance.boundary_work += balance.pending_boundary + bc_before;
    balance.pending_external = ext_after;
    balance.pending_boundary = bc_after;
  }
} // namespace shard::time
