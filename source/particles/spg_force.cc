// SPDX-License-Identifier: LGPL-2.1-or-later
#include <shard/base/parallel.h>
#include <shard/base/quiet_wait.h>
#include <shard/base/sections.h>
#include <shard/base/tensor.h>
#include <shard/particles/spg_force.h>

#include <deal.II/base/mpi.h>

#include <algorithm>
#include <cmath>
#include <iostream>
#include <map>
#include <sstream>

namespace shard::particles
{
  using namespace dealii;

  namespace
  {
    constexpr unsigned int batch_size = materials::point_batch_size;

    /// Determinant and inverse of a row-major 3x3 matrix.
    double
    invert(const double *a, double *inv)
    {
      inv[0]           = a[4] * a[8] - a[5] * a[7];
      inv[1]           = a[2] * a[7] - a[1] * a[8];
      inv[2]           = a[1] * a[5] - a[2] * a[4];
      inv[3]           = a[5] * a[6] - a[3] * a[8];
      inv[4]           = a[0] * a[8] - a[2] * a[6];
      inv[5]           = a[2] * a[3] - a[0] * a[5];
      inv[6]           = a[3] * a[7] - a[4] * a[6];
      inv[7]           = a[1] * a[6] - a[0] * a[7];
      inv[8]           = a[0] * a[4] - a[1] * a[3];
      const double det = a[0] * inv[0] + a[1] * inv[3] + a[2] * inv[6];
      for (unsigned int k = 0; k < 9; ++k)
        inv[k] /= det;
      return det;
    }

    /// V P = scale (sigma - q I) F^-T with scale = V J (row-major 3x3 into @p vp); sigma as
    /// (xx, yy, zz, yz, xz, xy), @p F_inv row-major.
    void
    volume_times_piola(const double *sig, const double q, const double *F_inv, const double scale, double *vp)
    {
      const double s[3][3] = {{sig[0] - q, sig[5], sig[4]}, {sig[5], sig[1] - q, sig[3]}, {sig[4], sig[3], sig[2] - q}};
      for (unsigned int a = 0; a < 3; ++a)
        for (unsigned int b = 0; b < 3; ++b)
          vp[3 * a + b] =
            scale * (s[a][0] * F_inv[3 * b] + s[a][1] * F_inv[3 * b + 1] + s[a][2] * F_inv[3 * b + 2]);
    }

    /// Smallest principal stretch of F. It scales the particle spacing for the stable step:
    /// under isochoric crushing J^(1/3) stays near 1 while the spacing along the crushing
    /// direction shrinks.
    double
    smallest_stretch(const double *F)
    {
      return tensor::principal_stretches(F)[0];
    }

    /// The offsets of consecutive parts of @p counts entries each (counts.size() + 1 of them).
    std::vector<int>
    offsets_of(const std::vector<int> &counts)
    {
      std::vector<int> offsets(counts.size() + 1, 0);
      for (std::size_t r = 0; r < counts.size(); ++r)
        offsets[r + 1] = offsets[r] + counts[r];
      return offsets;
    }
  } // namespace

  bool
  SpgForce::declare_parameters(ParameterHandler &prm)
  {
    if (!first_declaration())
      return false;
    prm.enter_subsection(sections::particle_formulation);
    prm.add_parameter("smoothing", smoothing_text_,
                      "two-level: direct displacement smoothing, u = A d at the particles and F from the gradients "
                      "of the smoothing functions (default). none: direct nodal integration of the RK functions "
                      "with the coefficients as nodal values (for comparison).",
                      Patterns::Selection("two-level|none"));
    prm.add_parameter("stabilization", stabilization_text_,
                      "Remedy against odd-even modes (doc/theory/spg_stabilization.md): residual (R2, default): "
                      "force from W = alpha/2 sum V M / a^2 |d - A d|^2; filter (R1): every N steps d <- A d and "
                      "v <- A v; none (R0).",
                      Patterns::Selection("residual|filter|none"));
    prm.add_parameter("residual coefficient", options_.residual_coefficient,
                      "alpha of the residual stabilization. Unit: 1. Range: 0 to 10; the spectral test passes from "
                      "0.03 on, 0.1 is the default.",
                      Patterns::Double(0, 10));
    prm.add_parameter("filter interval", options_.filter_interval,
                      "N of the filter (steps between two smoothings, like LS-DYNA's SMSTEP). Unit: steps. Range: >= 1.",
                      Patterns::Integer(1));
    prm.add_parameter("bulk viscosity linear", viscosity_.q1,
                      "Linear coefficient Q1 of the bulk viscosity q = rho L (Q2 L tr(D)^2 - Q1 c tr(D)), applied "
                      "in compression (tr(D) < 0) like LS-DYNA's default for solids; damps the ringing behind "
                      "shock fronts. Its work is part of the internal energy. Unit: 1. Range: 0 to 1.",
                      Patterns::Double(0, 1));
    prm.add_parameter("bulk viscosity quadratic", viscosity_.q2,
                      "Quadratic coefficient Q2 of the bulk viscosity. Unit: 1. Range: 0 to 4.", Patterns::Double(0, 4));
    prm.add_parameter("gradient correction", correction_text_,
                      "Correction of the nodal gradients so that nodal integration meets the integration "
                      "constraint and passes the Galerkin patch test (doc/theory/spg_stabilization.md). consistent "
                      "(default): the smallest symmetric change of the gradients that keeps linear exactness, from "
                      "one conjugate-gradient solve at set-up and after every conversion. petrov-galerkin: corrected test functions only "
                      "(non-symmetric stiffness; on free surfaces the spectrum becomes complex and a free vibration "
                      "grows). none: the seed form, for comparison.",
                      Patterns::Selection("consistent|petrov-galerkin|none"));
    prm.add_parameter("correction coarse size", correction_coarse_size_,
                      "Edge of the aggregates of the coarse space that preconditions the consistent-correction "
                      "solve, in mean particle spacings; 0 solves with the Jacobi preconditioner alone, whose "
                      "iterations grow with the square of the particle region's size (decision 0009). The "
                      "result is the same to the solve tolerance. Unit: 1. Range: 0, or 2 to 50.",
                      Patterns::Double(0, 50));
    prm.leave_subsection();
    return true;
  }

  void
  SpgForce::check_parameters(const base::PrmSource &source) const
  {
    if (!(options_.residual_coefficient >= 0 && options_.residual_coefficient <= 10))
      source.fail(sections::particle_formulation + "/residual coefficient", std::to_string(options_.residual_coefficient),
                  "must be in [0, 10]. Unit: 1.");
    if (correction_coarse_size_ != 0 && !(correction_coarse_size_ >= 2 && correction_coarse_size_ <= 50))
      source.fail(sections::particle_formulation + "/correction coarse size", std::to_string(correction_coarse_size_),
                  "must be 0 (no coarse space) or in [2, 50]. Unit: mean particle spacings.");
  }

  void
  SpgForce::prepare(const mesh::Discretization &discretization, ParticleSet &particles,
                    const materials::MaterialLibrary &library)
  {
    particles_      = &particles;
    discretization_ = &discretization;
    active_         = particles.active();
    evaluated_      = false;
    options_.smoothing     = smoothing_text_ == "none" ? Smoothing::none : Smoothing::two_level;
    options_.stabilization = stabilization_text_ == "filter" ? Stabilization::filter :
                             stabilization_text_ == "none"   ? Stabilization::none :
                                                               Stabilization::residual;
    options_.correction    = correction_text_ == "none"            ? Correction::none :
                             correction_text_ == "petrov-galerkin" ? Correction::petrov_galerkin :
                                                                     Correction::consistent;
    if (!active_)
      return;
    // The rows of broken bonds (ParticleSet::prepare() leaves them plain): rebuilt now, or, with
    // the consistent correction, after its solve, which needs every row linearly exact.
    if (options_.correction != Correction::consistent)
      particles.rebuild_broken_rows();
    const auto        &st = particles.stencils();
    const unsigned int n  = st.n_i;
    const auto        &bodies = discretization.bodies();

    // Material groups: runs of owned rows with the same material (rows are sorted by body).
    {
      std::vector<const materials::Material *> materials;
      std::vector<unsigned int>                group_of(n);
      std::vector<double>                      positions(3 * std::size_t(n));
      for (unsigned int i = 0; i < n; ++i)
        {
          const auto *m = &library.get(bodies[particles.body(i)].material);
          if (materials.empty() || materials.back() != m)
            materials.push_back(m);
          group_of[i] = materials.size() - 1;
          std::copy_n(particles.position(i).data(), 3, &positions[3 * std::size_t(i)]);
        }
      points_.build(materials, group_of, positions.data());
    }
    F_.assign(9 * n, 0.);
    for (unsigned int i = 0; i < n; ++i)
      F_[9 * i] = F_[9 * i + 4] = F_[9 * i + 8] = 1.;
    stress_.assign(6 * n, 0.);
    q_.assign(n, 0.);
    density_.resize(n);
    length_.resize(n);
    std::vector<double> lambda(n);
    for (unsigned int i = 0; i < n; ++i)
      {
        const auto  *m = &points_.material(i);
        const auto  &h = particles.spacing(i);
        density_[i]    = m->density();
        length_[i]     = std::min({h[0], h[1], h[2]});
        const double a = particles.mean_support_radius(i);
        const double c = m->initial_wave_speed();
        lambda[i]      = particles.volume(i) * m->density() * c * c / (a * a);
      }
    op_.reinit(st, options_, lambda);
    volume_factor_.assign(n, 1.);
    dk_.assign(3 * st.n_k, 0.);
    fk_.assign(3 * st.n_k, 0.);
    u_.assign(3 * st.n_j, 0.);
    Fnew_.assign(9 * n, 0.);
    VP_.assign(9 * n, 0.);

    if (options_.correction == Correction::petrov_galerkin)
      {
        // Integration-constraint terms summed over ranks, xi_K = (b_K - c_K) / w_K.
        std::vector<double> c(3 * st.n_k), b(3 * st.n_k), w(st.n_k), volume(n);
        for (unsigned int i = 0; i < n; ++i)
          volume[i] = particles.volume(i);
        op_.integration_terms(volume.data(), particles.area_vectors().data(), c.data(), b.data(), w.data());
        mesh::Vector cv, bv, wv;
        for (auto *v : {&cv, &bv, &wv})
          discretization.initialize_vector(*v);
        for (unsigned int k = 0; k < st.n_k; ++k)
          for (unsigned int i = 0; i < 3; ++i)
            {
              const unsigned int j = particles.local_dof(k) + i;
              cv.local_element(j) += c[3 * k + i];
              bv.local_element(j) += b[3 * k + i];
              wv.local_element(j) += w[k];
            }
        for (auto *v : {&cv, &bv, &wv})
          v->compress(VectorOperation::add);
        for (unsigned int k = 0; k < st.n_i; ++k)
          for (unsigned int i = 0; i < 3; ++i)
            {
              const unsigned int j = particles.local_dof(k) + i;
              cv.local_element(j)  = wv.local_element(j) > 0 ? (bv.local_element(j) - cv.local_element(j)) /
                                                                  wv.local_element(j) :
                                                                0.;
            }
        cv.update_ghost_values();
        std::vector<double> xi(3 * st.n_k);
        for (unsigned int k = 0; k < st.n_k; ++k)
          for (unsigned int i = 0; i < 3; ++i)
            xi[3 * k + i] = cv.local_element(particles.local_dof(k) + i);
        op_.set_gradient_correction(std::move(xi));
      }
    if (options_.correction == Correction::consistent)
      prepare_consistent_correction(particles);
    // The correction rewrote G in place: the gathers' copies in transposed order follow it.
    op_.copy_transposed_values();
  }

  void
  SpgForce::prepare_consistent_correction(ParticleSet &particles)
  {
    const auto        &st = particles_->stencils();
    const auto        &X  = discretization_->reference_positions();
    std::vector<Point3> position(st.n_j);
    for (unsigned int j = 0; j < st.n_j; ++j)
      for (unsigned int c = 0; c < 3; ++c)
        position[j][c] = X.local_element(particles_->local_dof(j) + c);
    std::vector<double>       volume(st.n_i);
    std::vector<unsigned int> component(st.n_i);
    const unsigned int        n_components = particles_->n_components();
    for (unsigned int i = 0; i < st.n_i; ++i)
      {
        volume[i]    = particles_->volume(i);
        component[i] = particles_->component(i);
      }
    const ConsistentCorrection correction(st, position, volume.data());

    // Arrays over the rows J (3 per particle) move through one distributed vector (not needed,
    // and not allocated, on one rank with every J owned: below).
    mesh::Vector work;
    const auto to_vector = [&](const std::vector<double> &a, const unsigned int n) {
      work = 0.;
      for (unsigned int j = 0; j < n; ++j)
        for (unsigned int c = 0; c < 3; ++c)
          work.local_element(particles_->local_dof(j) + c) = a[3 * j + c];
    };
    const auto from_vector = [&](std::vector<double> &a) {
      for (unsigned int j = 0; j < st.n_j; ++j)
        for (unsigned int c = 0; c < 3; ++c)
          a[3 * j + c] = work.local_element(particles_->local_dof(j) + c);
    };
    const MPI_Comm comm = discretization_->communicator();
    CorrectionExchange exchange;
    exchange.sum  = [comm](std::vector<double> &a) {
      const std::vector<double> local(a);
      Utilities::MPI::sum(local, comm, a);
    };
    exchange.rank = Utilities::MPI::this_mpi_process(comm);
    if (Utilities::MPI::n_mpi_processes(comm) == 1 && st.n_j == st.n_i)
      {
        // One rank and every J owned: assembling and distributing change nothing (the round
        // trip through the distributed vector cost about 2 % of the particle set-up of contrib/bench).
        exchange.assemble = exchange.distribute = [](std::vector<double> &) {};
      }
    else
      {
        discretization_->initialize_vector(work);
        exchange.assemble = [&](std::vector<double> &a) {
          to_vector(a, st.n_j);
          work.compress(VectorOperation::add);
          work.update_ghost_values();
          from_vector(a);
        };
        exchange.distribute = [&](std::vector<double> &a) {
          to_vector(a, st.n_i);
          work.update_ghost_values();
          from_vector(a);
        };
      }
    exchange.to_root = [comm](const std::vector<double> &a) {
      const int        n_ranks = Utilities::MPI::n_mpi_processes(comm);
      const bool       root    = Utilities::MPI::this_mpi_process(comm) == 0;
      int              n       = static_cast<int>(a.size());
      std::vector<int> counts(root ? n_ranks : 0);
      int              ierr = MPI_Gather(&n, 1, MPI_INT, counts.data(), 1, MPI_INT, 0, comm);
      AssertThrowMPI(ierr);
      const auto          offsets = offsets_of(counts); // one entry (0) on the other ranks
      std::vector<double> all(offsets.back());
      ierr = MPI_Gatherv(a.data(), n, MPI_DOUBLE, all.data(), counts.data(), offsets.data(), MPI_DOUBLE, 0, comm);
      AssertThrowMPI(ierr);
      return all;
    };
    exchange.from_root = [comm](const std::vector<double> &all, const std::vector<int> &lengths,
                                const unsigned int n_mine) {
      const bool          root    = Utilities::MPI::this_mpi_process(comm) == 0;
      const auto          offsets = offsets_of(lengths); // lengths: on rank 0 only
      std::vector<double> mine(n_mine);
      MPI_Request         request;
      int ierr = MPI_Iscatterv(all.data(), lengths.data(), offsets.data(), MPI_DOUBLE, mine.data(),
                               static_cast<int>(n_mine), MPI_DOUBLE, 0, comm, &request);
      AssertThrowMPI(ierr);
      // The other ranks wait while rank 0 solves the coarse problem, without spinning.
      if (root)
        ierr = MPI_Wait(&request, MPI_STATUS_IGNORE);
      else
        base::wait_quietly(request);
      AssertThrowMPI(ierr);
      return mine;
    };
    std::vector<double> lambda;
    const auto          solve =
      solve_consistent_correction(correction, particles_->area_vectors().data(), position, component, n_components,
                                  exchange, lambda, 1e-10, 50000, correction_coarse_size_);
    correction_solve_ = solve;
    if (solve.converged && Utilities::MPI::this_mpi_process(comm) == 0)
      std::cerr << "shard: particles: consistent gradient correction: " << solve.iterations
                << " conjugate-gradient iterations, defect " << solve.initial_defect << " -> " << solve.final_defect
                << " m^2, coarse space " << solve.coarse_functions << " functions on " << solve.aggregates
                << " aggregates\n";
    if (!solve.converged && Utilities::MPI::this_mpi_process(comm) == 0)
      std::cerr << "shard: warning: the consistent gradient correction did not converge (" << solve.iterations
                << " iterations, defect " << solve.initial_defect << " -> " << solve.final_defect
                << "); the Galerkin patch test holds only to that level.\n";
    particles.replace_gradients(correction.corrected_gradients(lambda.data()));
    const auto limited = Utilities::MPI::sum(correction.limited_rows(), comm);
    if (limited > 0 && Utilities::MPI::this_mpi_process(comm) == 0)
      std::cerr << "shard: particles: " << limited
                << " gradient rows keep a limited consistent correction (no entry above "
                << ConsistentCorrection::max_correction_ratio << " / spacing; "
                   "doc/theory/spg_stabilization.md, \"Correction limiter\")\n";
    // Rows with broken bonds keep their plain RK gradients (doc/manual/failure.md).
    particles.rebuild_broken_rows();
  }

  std::map<unsigned long long, SpgForce::SavedParticle>
  SpgForce::save_state() const
  {
    std::map<unsigned long long, SavedParticle> out;
    for (unsigned int i = 0; i < n_owned(); ++i)
      {
        SavedParticle p;
        p.volume = particles_->volume(i);
        p.q      = q_[i];
        p.jacobian = jacobian(i);
        p.volume_factor = volume_factor_[i];
        std::copy_n(op_.last_residual(i), 3, p.residual.begin());
        std::copy_n(op_.residual_offset(i), 3, p.residual_offset.begin());
        std::copy(&stress_[6 * i], &stress_[6 * i] + 6, p.stress.begin());
        p.state.assign(state(i), state(i) + points_.n_slots(i));
        out.emplace(particles_->global_id(i), std::move(p));
      }
    return out;
  }

  base::KeyedRecords
  SpgForce::portable_state(const std::function<unsigned long long(unsigned int)> &key_of) const
  {
    base::KeyedRecords  out;
    std::vector<double> r;
    for (unsigned int i = 0; i < n_owned(); ++i)
      {
        r.assign(&stress_[6 * i], &stress_[6 * i] + 6);
        r.push_back(q_[i]);
        r.insert(r.end(), state(i), state(i) + points_.n_slots(i));
        r.push_back(volume_factor_[i]);
        r.insert(r.end(), op_.residual_offset(i), op_.residual_offset(i) + 3);
        out.add(key_of(i), r.data(), r.data() + r.size());
      }
    return out;
  }

  void
  SpgForce::restore_portable(const base::KeyedLookup                                 &saved,
                             const std::function<unsigned long long(unsigned int)> &key_of)
  {
    for (unsigned int i = 0; i < n_owned(); ++i)
      {
        const std::string  what    = "particle at node " + std::to_string(key_of(i));
        const auto         r       = saved.find(key_of(i), what);
        const unsigned int n_slots = points_.n_slots(i);
        if (r.size != 11 + n_slots)
          throw std::runtime_error(what + " has another number of history values");
        set_state(i, r.values, r.values + 7, r.values[6]);
        set_volume_factor(i, r.values[7 + n_slots]);
        set_residual_offset(i, r.values + 8 + n_slots);
      }
  }

  void
  SpgForce::set_state(const unsigned int i, const double *stress, const double *history, const double q)
  {
    evaluated_ = false;
    std::copy(stress, stress + 6, &stress_[6 * i]);
    double *state = points_.state(i);
    std::copy(history, history + points_.n_slots(i), state);
    // Fields of the reference position are the particle's own, not an average of its sources.
    points_.material(i).set_position_fields(1, particles_->position(i).data(), state);
    q_[i] = q;
  }

  void
  SpgForce::keep_residuals(const mesh::Vector &d, const std::map<unsigned long long, SavedParticle> &saved)
  {
    if (!active_ || options_.stabilization != Stabilization::residual)
      return;
    evaluated_ = false;
    gather(d, dk_);
    std::vector<unsigned int> rows(n_owned());
    std::vector<double>       target(3 * n_owned(), 0.);
    for (unsigned int i = 0; i < n_owned(); ++i)
      {
        rows[i]       = i;
        const auto it = saved.find(particles_->global_id(i));
        if (it != saved.end())
          std::copy(it->second.residual.begin(), it->second.residual.end(), &target[3 * i]);
      }
    op_.rebase_residual(dk_.data(), rows, target.data());
  }

  double
  SpgForce::reset_deformation(const mesh::Vector &d)
  {
    if (!active_)
      return 0.;
    evaluated_ = false;
    set_kinematics(d);
    if (options_.stabilization != Stabilization::residual)
      return 0.;
    std::fill(fk_.begin(), fk_.end(), 0.);
    return op_.subtract_residual_force(dk_.data(), fk_.data());
  }

  void
  SpgForce::set_kinematics(const mesh::Vector &d)
  {
    gather(d, dk_);
    op_.displacement(dk_.data(), u_.data());
    op_.deformation_gradient(u_.data(), F_.data());
  }

  double
  SpgForce::refresh_forces(const mesh::Vector &d, mesh::Vector &delta, const std::vector<unsigned int> &a_rows,
                           const std::vector<unsigned int> &g_rows)
  {
    if (!active_)
      return 0.;
    op_.copy_transposed_values(a_rows, g_rows);
    // The residual of a rebuilt row goes on from where it was (SpgOperator::rebase_residual()).
    if (options_.stabilization == Stabilization::residual)
      {
        gather(d, dk_);
        std::vector<unsigned int> owned_a;
        for (const unsigned int r : a_rows)
          if (r < n_owned())
            owned_a.push_back(r);
        op_.rebase_residual(dk_.data(), owned_a);
      }
    const std::vector<double> old = fk_;
    // det F before the new rows act, for the volume factors (J = c det F continuous; update_vp
    // runs once per particle).
    std::vector<double> det_before(n_owned());
    for (unsigned int i = 0; i < n_owned(); ++i)
      {
        double Fi[9];
        det_before[i] = invert(&F_[9 * i], Fi);
      }
    const auto update_vp = [&](const unsigned int i) {
      double       Fi[9];
      const double det = invert(&F_[9 * i], Fi);
      if (det != det_before[i] && det > 0)
        volume_factor_[i] *= det_before[i] / det;
      volume_times_piola(&stress_[6 * i], q_[i], Fi, particles_->volume(i) * volume_factor_[i] * det, &VP_[9 * i]);
    };
    if (evaluated_)
      {
        // Only what the changed rows reach (the same numbers as the full evaluation below).
        gather(d, dk_);
        std::vector<unsigned int> changed;
        const double              w =
          op_.refresh_internal_force(dk_.data(), u_.data(), F_.data(), VP_.data(), update_vp, fk_.data(), a_rows, g_rows,
                                     changed);
        for (const unsigned int k : changed)
          for (unsigned int c = 0; c < 3; ++c)
            delta.local_element(particles_->local_dof(k) + c) += fk_[3 * k + c] - old[3 * k + c];
        return w;
      }
    set_kinematics(d);
    // V P = V J (sigma - q I) F^-T from the stored stress and bulk viscosity.
    for (unsigned int i = 0; i < n_owned(); ++i)
      update_vp(i);
    std::fill(fk_.begin(), fk_.end(), 0.);
    op_.subtract_internal_force(VP_.data(), fk_.data());
    const double w =
      options_.stabilization == Stabilization::residual ? op_.subtract_residual_force(dk_.data(), fk_.data()) : 0.;
    for (unsigned int k = 0; k < particles_->stencils().n_k; ++k)
      for (unsigned int c = 0; c < 3; ++c)
        delta.local_element(particles_->local_dof(k) + c) += fk_[3 * k + c] - old[3 * k + c];
    evaluated_ = options_.stabilization != Stabilization::filter;
    return w;
  }

  double
  SpgForce::jacobian(const unsigned int i) const
  {
    double inv[9];
    return volume_factor_[i] * invert(&F_[9 * i], inv);
  }

  double
  SpgForce::current_stable_dt() const
  {
    double dt = 1e300;
    for (unsigned int i = 0; i < n_owned(); ++i)
      dt = std::min(dt, length_[i] * smallest_stretch(&F_[9 * i]) / points_.material(i).initial_wave_speed());
    dt /= viscosity_.initial_step_factor();
    return Utilities::MPI::min(dt, discretization_->communicator());
  }

  double
  SpgForce::initial_stable_dt() const
  {
    double dt = 1e300;
    for (unsigned int i = 0; i < n_owned(); ++i)
      dt = std::min(dt, length_[i] / points_.material(i).initial_wave_speed());
    // The linear bulk viscosity lowers the step from the first force evaluation on (see
    // add_internal_forces); start with that step, so that it does not change at step 1.
    dt /= viscosity_.initial_step_factor();
    return Utilities::MPI::min(dt, discretization_->communicator());
  }

  void
  SpgForce::gather(const mesh::Vector &v, std::vector<double> &out) const
  {
    const unsigned int n_k = particles_->stencils().n_k;
    base::for_each_range(n_k, 1024, [&](const unsigned int begin, const unsigned int end) {
      for (unsigned int k = begin; k < end; ++k)
        {
          const unsigned int j = particles_->local_dof(k);
          out[3 * k]           = v.local_element(j);
          out[3 * k + 1]       = v.local_element(j + 1);
          out[3 * k + 2]       = v.local_element(j + 2);
        }
    });
  }

  double
  SpgForce::filter(const mesh::Vector &mass, const mesh::Vector &f, mesh::Vector &d, mesh::Vector &v)
  {
    const unsigned int  n = n_owned();
    std::vector<double> smoothed(3 * n);
    double              added = 0;
    gather(d, dk_);
    op_.smooth_owned(dk_.data(), smoothed.data());
    for (unsigned int i = 0; i < n; ++i)
      for (unsigned int c = 0; c < 3; ++c)
        {
          const unsigned int j = particles_->local_dof(i) + c;
          // Internal-energy change to first order: f_int . delta d = -(f - f_ext) . delta d.
          added -= f.local_element(j) * (smoothed[3 * i + c] - d.local_element(j));
          d.local_element(j) = smoothed[3 * i + c];
        }
    gather(v, dk_);
    op_.smooth_owned(dk_.data(), smoothed.data());
    for (unsigned int i = 0; i < n; ++i)
      for (unsigned int c = 0; c < 3; ++c)
        {
          const unsigned int j = particles_->local_dof(i) + c;
          const double       vn = smoothed[3 * i + c], vo = v.local_element(j);
          added += 0.5 * mass.local_element(j) * (vn * vn - vo * vo);
          v.local_element(j) = vn;
        }
    return added;
  }

  std::string
  SpgForce::describe(const unsigned int i) const
  {
    const auto        &x = particles_->position(i);
    std::ostringstream out;
    out << "particle " << particles_->global_id(i) << " of body '"
        << discretization_->bodies()[particles_->body(i)].name << "' (reference position " << x[0] << ", " << x[1]
        << ", " << x[2] << ") m";
    return out.str();
  }

  void
  SpgForce::fail(const unsigned int i, const unsigned int step, const std::string &what) const
  {
    throw Instability("step " + std::to_string(step) + ": " + what + " at " + describe(i));
  }

  const double *
  SpgForce::state(const unsigned int i) const
  {
    return points_.state(i);
  }

  double
  SpgForce::state_value(const unsigned int i, const std::string &name) const
  {
    return points_.state_value(i, name);
  }

  ParticleForceResult
  SpgForce::add_internal_forces(const mesh::Vector &d, const double dt, const unsigned int step, mesh::Vector &f)
  {
    ParticleForceResult result;
    if (!active_)
      return result;
    gather(d, dk_);
    op_.displacement(dk_.data(), u_.data());
    op_.deformation_gradient(u_.data(), Fnew_.data());

    // Batches of batch_size particles of one material; each writes only its own particles.
    const auto &batches = points_.batches();
    // One partial per batch, combined in batch order below (the same for any thread count).
    struct Partial
    {
      double       stable_dt = 1e300;
      unsigned int smallest  = 0;
    };
    work_.resize(n_owned());
    std::vector<Partial> partial(batches.size());
    base::for_each_chunk(batches.size(), 1, [&](const unsigned int bi, unsigned int, unsigned int) {
      Partial           &part = partial[bi];
      const unsigned int b0   = batches[bi].begin;
      const unsigned int nb   = batches[bi].end - b0;
      // (The inputs of the material call are zeroed: GCC cannot see that the loop below fills
      // the nb entries the call reads.)
      double de[6 * batch_size] = {}, J[batch_size] = {}, length[batch_size] = {};
      double c[batch_size], stress_old[6 * batch_size], volume_mid[batch_size], F_inv[9 * batch_size];
      for (unsigned int k = 0; k < nb; ++k)
        {
          const unsigned int i  = b0 + k;
          const double      *Fo = &F_[9 * i], *Fn = &Fnew_[9 * i];
          double             Fm[9], Fm_inv[9], L[9];
          for (unsigned int a = 0; a < 9; ++a)
            Fm[a] = 0.5 * (Fo[a] + Fn[a]);
          const double det_m = volume_factor_[i] * invert(Fm, Fm_inv);
          J[k]               = volume_factor_[i] * invert(Fn, &F_inv[9 * k]);
          if (!(J[k] > 0) || !(det_m > 0))
            fail(i, step, "inverted particle (det F = " + std::to_string(J[k]) + ")");
          // dt L = (F_new - F_old) F_mid^-1.
          for (unsigned int a = 0; a < 3; ++a)
            for (unsigned int b = 0; b < 3; ++b)
              {
                double s = 0;
                for (unsigned int m = 0; m < 3; ++m)
                  s += (Fn[3 * a + m] - Fo[3 * a + m]) * Fm_inv[3 * m + b];
                L[3 * a + b] = s;
              }
          double *e = &de[6 * k];
          e[0]      = L[0];
          e[1]      = L[4];
          e[2]      = L[8];
          e[3]      = 0.5 * (L[5] + L[7]);
          e[4]      = 0.5 * (L[2] + L[6]);
          e[5]      = 0.5 * (L[1] + L[3]);
          double W[3][3], R[3][3];
          for (unsigned int a = 0; a < 3; ++a)
            for (unsigned int b = 0; b < 3; ++b)
              W[a][b] = 0.5 * (L[3 * a + b] - L[3 * b + a]) / dt;
          tensor::hughes_winget_rotation(W, dt, R);
          double *sig = &stress_[6 * i];
          tensor::rotate_symmetric(R, sig);
          std::copy(sig, sig + 6, &stress_old[6 * k]);
          length[k]     = length_[i] * std::cbrt(J[k]);
          volume_mid[k] = particles_->volume(i) * det_m;
        }

      points_.update(batches[bi], dt, de, J, length, stress_.data(), c);

      for (unsigned int k = 0; k < nb; ++k)
        {
          const unsigned int i   = b0 + k;
          const double      *sig = &stress_[6 * i];
          const double      *e   = &de[6 * k];
          double work = materials::stress_work(&stress_old[6 * k], sig, e, volume_mid[k], materials::WorkOrder::pairs);
          if (!std::isfinite(work) || !std::isfinite(c[k]))
            fail(i, step, "non-finite stress (sigma_xx = " + std::to_string(sig[0]) + " Pa)");
          // Bulk viscosity in compression (not stored; its work is dissipated into internal
          // energy, with the mean of the q of both ends of the step).
          const double trd = e[0] + e[1] + e[2];
          const double q   = viscosity_.apply(density_[i] / J[k], length[k], c[k], trd, dt, volume_mid[k], q_[i], work);
          work_[i]         = work;
          // Step limit of the viscosity; the spacing is the reference spacing times the smallest
          // principal stretch.
          const double spacing = length_[i] * smallest_stretch(&Fnew_[9 * i]);
          const double dt_i    = viscosity_.stable_step(spacing, c[k], trd, dt);
          if (dt_i < part.stable_dt)
            {
              part.stable_dt = dt_i;
              part.smallest  = i;
            }
          volume_times_piola(sig, q, &F_inv[9 * k], particles_->volume(i) * J[k], &VP_[9 * i]);
        }
    });
    // The work summed in particle order, as in one pass over all particles.
    for (unsigned int i = 0; i < n_owned(); ++i)
      result.internal_energy += work_[i];
    for (const auto &p : partial)
      {
        // The first particle of the smallest step, as in one pass over all particles.
        if (p.stable_dt < result.stable_dt)
          {
            result.stable_dt = p.stable_dt;
            smallest_step_   = p.smallest;
          }
      }
    std::fill(fk_.begin(), fk_.end(), 0.);
    op_.subtract_internal_force(VP_.data(), fk_.data());
    if (options_.stabilization == Stabilization::residual)
      result.stabilization_energy = op_.subtract_residual_force(dk_.data(), fk_.data());
    const unsigned int n_k = particles_->stencils().n_k;
    base::for_each_range(n_k, 1024, [&](const unsigned int begin, const unsigned int end) {
      for (unsigned int k = begin; k < end; ++k)
        {
          const unsigned int j = particles_->local_dof(k);
          f.local_element(j) += fk_[3 * k];
          f.local_element(j + 1) += fk_[3 * k + 1];
          f.local_element(j + 2) += fk_[3 * k + 2];
        }
    });
    F_.swap(Fnew_);
    // The refresh after broken bonds may reuse this evaluation (not with the filter, which
    // changes d and reuses dk_ as scratch).
    evaluated_ = options_.stabilization != Stabilization::filter;
    return result;
  }

  void
  SpgForce::physical_displacement(mesh::Vector &out) const
  {
    for (unsigned int i = 0; i < n_owned(); ++i)
      for (unsigned int c = 0; c < 3; ++c)
        out.local_element(particles_->local_dof(i) + c) = u_[3 * i + c];
  }

  std::size_t
  SpgForce::memory_consumption() const
  {
    const auto bytes = [](const auto &v) { return v.capacity() * sizeof(v[0]); };
    return sizeof(*this) - sizeof(op_) + op_.memory_consumption() + points_.memory_consumption() + bytes(F_) +
           bytes(stress_) + bytes(q_) + bytes(density_) + bytes(length_) + bytes(dk_) + bytes(u_) + bytes(fk_) +
           bytes(Fnew_) + bytes(VP_) + bytes(work_);
  }
} // namespace shard::particles
