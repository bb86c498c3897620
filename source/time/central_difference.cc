// SPDX-License-Identifier: LGPL-2.1-or-later
#include <shard/base/sections.h>
#include <shard/time/central_difference.h>
#include <shard/time/rigid_bodies.h>

#include <deal.II/base/mpi.h>
#include <deal.II/base/tensor.h>

#include <algorithm>

namespace shard::time
{
  using namespace dealii;

  bool
  CentralDifference::declare_parameters(ParameterHandler &prm)
  {
    if (!first_declaration())
      return false;
    prm.enter_subsection(sections::time_integration);
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
    const std::string p = sections::time_integration + "/";
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
  CentralDifference::drift(const double dt, mesh::Vector &v, mesh::Vector &d)
  {
    // Rigid bodies: the exact rotation instead of the straight drift of each node.
    rigid_.correct_drift(dt, v, d);
    const unsigned int n  = d.locally_owned_size();
    double            *dp = d.begin();
    const double      *vp = v.begin();
    for (unsigned int i = 0; i < n; ++i)
      dp[i] += dt * vp[i];
    // ... and their velocities turn with them.
    rigid_.rotate_velocities(v);
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
    // Rigid bodies move as one (their constraint forces do no work on the rigid motion).
    rigid_.project(d, mass, v);
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

  void
  RigidBodies::prepare(const mesh::Discretization &discretization, const materials::MaterialLibrary &materials,
                       const mesh::Vector &mass)
  {
    discretization_ = &discretization;
    mass_           = &mass;
    bodies_.clear();
    nodes_.clear();
    partitioner_.reset();
    for (unsigned int b = 0; b < discretization.bodies().size(); ++b)
      if (materials.get(discretization.bodies()[b].material).rigid())
        bodies_.push_back(b);
  }

  void
  RigidBodies::refresh() const
  {
    // The node lists follow the layout (conversions move the vectors to a new partitioner).
    if (partitioner_ == discretization_->partitioner())
      return;
    partitioner_ = discretization_->partitioner();
    nodes_.clear();
    for (const unsigned int b : bodies_)
      nodes_.push_back(discretization_->body_nodes(b));
  }

  std::vector<RigidBodies::Motion>
  RigidBodies::motions(const mesh::Vector &d, const mesh::Vector &mass, const mesh::Vector &v) const
  {
    refresh();
    const auto   &X  = discretization_->reference_positions();
    const double *dp = d.begin(), *mp = mass.begin(), *vp = v.begin();
    // Per body: M, sum m x, P = sum m v, L_0 = sum m x × v, J_0 = sum m (|x|^2 1 - x x) (upper
    // triangle), all about the origin; summed over ranks in one call.
    std::vector<double> sums(16 * bodies_.size(), 0.);
    for (unsigned int k = 0; k < bodies_.size(); ++k)
      {
        double *q = &sums[16 * k];
        for (const unsigned int j : nodes_[k])
          {
            const double  m    = mp[j];
            const double  x[3] = {X.local_element(j) + dp[j], X.local_element(j + 1) + dp[j + 1],
                                  X.local_element(j + 2) + dp[j + 2]};
            const double *u    = vp + j;
            q[0] += m;
            for (unsigned int i = 0; i < 3; ++i)
              {
                q[1 + i] += m * x[i];
                q[4 + i] += m * u[i];
              }
            q[7] += m * (x[1] * u[2] - x[2] * u[1]);
            q[8] += m * (x[2] * u[0] - x[0] * u[2]);
            q[9] += m * (x[0] * u[1] - x[1] * u[0]);
            const double r2 = x[0] * x[0] + x[1] * x[1] + x[2] * x[2];
            q[10] += m * (r2 - x[0] * x[0]);
            q[11] += m * (r2 - x[1] * x[1]);
            q[12] += m * (r2 - x[2] * x[2]);
            q[13] -= m * x[1] * x[2];
            q[14] -= m * x[0] * x[2];
            q[15] -= m * x[0] * x[1];
          }
      }
    Utilities::MPI::sum(sums, discretization_->communicator(), sums);
    std::vector<Motion> result(bodies_.size());
    for (unsigned int k = 0; k < bodies_.size(); ++k)
      {
        const double *q = &sums[16 * k];
        Motion       &b = result[k];
        b.mass          = q[0];
        if (!(b.mass > 0))
          continue;
        Tensor<1, 3> L;
        for (unsigned int i = 0; i < 3; ++i)
          {
            b.centre[i]   = q[1 + i] / b.mass;
            b.velocity[i] = q[4 + i] / b.mass;
            L[i]          = q[7 + i];
          }
        // About the centre of mass: L_c = L_0 - M c × V, J_c = J_0 - M (|c|^2 1 - c c).
        L -= b.mass * cross_product_3d(b.centre, b.velocity);
        Tensor<2, 3> J;
        J[0][0] = q[10];
        J[1][1] = q[11];
        J[2][2] = q[12];
        J[1][2] = J[2][1] = q[13];
        J[0][2] = J[2][0] = q[14];
        J[0][1] = J[1][0] = q[15];
        const double c2 = b.centre * b.centre;
        for (unsigned int i = 0; i < 3; ++i)
          for (unsigned int l = 0; l < 3; ++l)
            J[i][l] -= b.mass * ((i == l ? c2 : 0.) - b.centre[i] * b.centre[l]);
        b.omega = invert(J) * L;
      }
    return result;
  }

  void
  RigidBodies::project(const mesh::Vector &d, const mesh::Vector &mass, mesh::Vector &v) const
  {
    if (bodies_.empty())
      return;
    const auto  motion = motions(d, mass, v);
    const auto &X      = discretization_->reference_positions();
    const double *dp   = d.begin();
    double       *vp   = v.begin();
    for (unsigned int k = 0; k < bodies_.size(); ++k)
      for (const unsigned int j : nodes_[k])
        {
          Tensor<1, 3> r;
          for (unsigned int i = 0; i < 3; ++i)
            r[i] = X.local_element(j + i) + dp[j + i] - motion[k].centre[i];
          const Tensor<1, 3> u = motion[k].velocity + cross_product_3d(motion[k].omega, r);
          for (unsigned int i = 0; i < 3; ++i)
            vp[j + i] = u[i];
        }
  }

  void
  RigidBodies::correct_drift(const double dt, const mesh::Vector &v, mesh::Vector &d)
  {
    if (bodies_.empty())
      return;
    // The motion of the step from the rigid velocities v^{n+1/2} about the centre at d^n.
    const auto    motion = motions(d, *mass_, v);
    const auto   &X      = discretization_->reference_positions();
    double       *dp     = d.begin();
    turned_.clear();
    for (unsigned int k = 0; k < bodies_.size(); ++k)
      {
        const auto  &b     = motion[k];
        const double angle = b.omega.norm() * dt;
        const Tensor<1, 3> axis = angle > 0 ? b.omega / b.omega.norm() : Tensor<1, 3>();
        const double cs = std::cos(angle), sn = std::sin(angle);
        for (const unsigned int j : nodes_[k])
          {
            Tensor<1, 3> r;
            for (unsigned int i = 0; i < 3; ++i)
              r[i] = X.local_element(j + i) + dp[j + i] - b.centre[i];
            // Rodrigues: the exact rotation by omega dt about the centre, less the straight
            // drift dt omega × r that the node's own update adds.
            const Tensor<1, 3> rotated =
              cs * r + sn * cross_product_3d(axis, r) + (1 - cs) * (axis * r) * axis;
            const Tensor<1, 3> straight = dt * cross_product_3d(b.omega, r);
            for (unsigned int i = 0; i < 3; ++i)
              dp[j + i] += rotated[i] - r[i] - straight[i];
            // The velocity at the turned position (omega is along the axis, so it is unchanged).
            const Tensor<1, 3> u = b.velocity + cross_product_3d(b.omega, rotated);
            for (unsigned int i = 0; i < 3; ++i)
              turned_.push_back(u[i]);
          }
      }
  }

  void
  RigidBodies::rotate_velocities(mesh::Vector &v) const
  {
    if (bodies_.empty())
      return;
    double     *vp = v.begin();
    std::size_t t  = 0;
    for (unsigned int k = 0; k < bodies_.size(); ++k)
      for (const unsigned int j : nodes_[k])
        for (unsigned int i = 0; i < 3; ++i)
          vp[j + i] = turned_[t++];
  }
} // namespace shard::time
