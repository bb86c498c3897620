// SPDX-License-Identifier: LGPL-2.1-or-later
#include <shard/simulation/explicit_step.h>

#include <deal.II/base/mpi.h>

#include <cmath>
#include <sstream>
#include <stdexcept>
#include <string>

namespace shard
{
  using namespace dealii;
  using base::Phase;

  base::KeyedRecords
  StepState::portable_state(const std::function<unsigned long long(unsigned int)> &key_of) const
  {
    base::KeyedRecords out;
    double             r[15];
    for (unsigned int j = 0; j < d.locally_owned_size(); j += 3)
      {
        double *x = r;
        for (const auto *vec : {&d, &v, &v_now, &f, &f_ext})
          for (unsigned int c = 0; c < 3; ++c)
            *x++ = vec->local_element(j + c);
        out.add(key_of(j), r, r + 15);
      }
    return out;
  }

  void
  StepState::restore_portable(const base::KeyedLookup                                 &saved,
                              const std::function<unsigned long long(unsigned int)> &key_of)
  {
    for (unsigned int j = 0; j < d.locally_owned_size(); j += 3)
      {
        const std::string what = "node " + std::to_string(key_of(j));
        const auto        r    = saved.find(key_of(j), what);
        if (r.size != 15)
          throw std::runtime_error(what + " has another number of values");
        const double *x = r.values;
        for (auto *vec : {&d, &v, &v_now, &f, &f_ext})
          for (unsigned int c = 0; c < 3; ++c)
            vec->local_element(j + c) = *x++;
      }
  }

  ExplicitStep::ExplicitStep(MPI_Comm comm, const Components &components, StepState &state,
                             std::function<void(const std::vector<unsigned int> &)> convert)
    : comm_(comm)
    , c_(components)
    , s_(state)
    , convert_(std::move(convert))
  {}

  void
  ExplicitStep::step_size()
  {
    const auto timer = c_.times.scope(Phase::step_size);
    s_.dt            = s_.dt_next;
  }

  void
  ExplicitStep::drift()
  {
    const auto timer = c_.times.scope(Phase::drift);
    c_.integrator.drift(s_.dt, s_.v, s_.d);
    s_.t += s_.dt;
    ++s_.step;
  }

  void
  ExplicitStep::exchange()
  {
    const auto timer = c_.times.scope(Phase::exchange);
    traffic_.count_step();
    // d and v: 8 bytes per owned entry another rank imports, each.
    const double ghost_bytes = 2. * sizeof(double) * s_.d.get_partitioner()->n_import_indices();
    s_.d.update_ghost_values();
    s_.v.update_ghost_values();
    traffic_.add(base::Traffic::ghost_values, ghost_bytes);
    traffic_.add(base::Traffic::contact_nodes, c_.contact.exchange(s_.step, s_.dt, s_.d, s_.v));
    // R1 filter steps smooth the particle coefficients and exchange once more. (The filter's
    // energy uses f, which still holds the force of the last step, f^{n-1}.)
    if (c_.spg.is_filter_step(s_.step))
      {
        c_.energy.add_filter_work(c_.spg.filter(s_.mass, s_.f, s_.d, s_.v));
        s_.d.update_ghost_values();
        s_.v.update_ghost_values();
        traffic_.add(base::Traffic::ghost_values, ghost_bytes);
      }
  }

  void
  ExplicitStep::internal_forces()
  {
    failure_.clear();
    to_convert_.clear();
    convert_now_ = false;
    {
      const auto timer = c_.times.scope(Phase::fe_force);
      s_.f             = 0;
      try
        {
          element_steps_ += c_.hex.n_local_elements();
          const auto r = c_.hex.add_internal_forces(s_.d, s_.v, s_.dt, s_.step, s_.f);
          s_.stable_dt = r.stable_dt;
          c_.energy.add_internal(r.internal_energy);
          c_.energy.add_hourglass(r.hourglass_energy);
        }
      catch (const Instability &e)
        {
          failure_ = e.what();
        }
    }
    if (c_.spg.active())
      {
        const auto timer = c_.times.scope(Phase::particle_force);
        try
          {
            particle_steps_ += c_.spg.n_owned();
            const auto r   = c_.spg.add_internal_forces(s_.d, s_.dt, s_.step, s_.f);
            s_.stable_dt   = std::min(s_.stable_dt, r.stable_dt);
            s_.particle_dt = r.stable_dt;
            c_.energy.add_internal(r.internal_energy);
            c_.energy.set_stabilization(r.stabilization_energy);
          }
        catch (const Instability &e)
          {
            failure_ += (failure_.empty() ? "" : "; ") + std::string(e.what());
          }
      }
  }

  void
  ExplicitStep::loads()
  {
    const auto timer = c_.times.scope(Phase::loads);
    s_.f_ext         = 0;
    c_.conditions.add_external_forces(s_.t, s_.f_ext);
    // A contact spring acts in series with the element stiffness at its node, so its limit
    // combines with the force step: 1/dt^2 = 1/dt_force^2 + 1/dt_contact^2.
    if (c_.contact.active())
      {
        const double dt_c = c_.contact.add_forces(s_.step, s_.dt, s_.f).stable_dt;
        s_.stable_dt      = 1. / std::sqrt(1. / (s_.stable_dt * s_.stable_dt) + 1. / (dt_c * dt_c));
      }
  }

  void
  ExplicitStep::accumulate()
  {
    {
      const auto timer = c_.times.scope(Phase::accumulate);
      s_.f.compress(VectorOperation::add);
      traffic_.add(base::Traffic::ghost_sums, sizeof(double) * s_.f.get_partitioner()->n_ghost_indices());
      traffic_.add(base::Traffic::contact_forces, c_.contact.accumulate(s_.f));
      s_.f += s_.f_ext;
      // Elements that meet a conversion criterion at the end of this step.
      if (c_.conversion.is_check_step(s_.step) && failure_.empty())
        to_convert_ = c_.conversion.candidates(c_.hex, s_.d);
      const double local[3] = {s_.stable_dt, failure_.empty() ? 0. : -1., to_convert_.empty() ? 0. : -1.};
      double       global[3];
      Utilities::MPI::min(ArrayView<const double>(local, 3), comm_, ArrayView<double>(global, 3));
      s_.stable_dt = global[0];
      convert_now_ = global[2] < 0;
      if (global[1] < 0)
        {
          std::string all;
          for (const auto &m : Utilities::MPI::all_gather(comm_, failure_))
            if (!m.empty())
              all += (all.empty() ? "" : "; ") + m;
          // A load that became non-finite is the likely cause: name it.
          throw Instability(all + non_finite_source());
        }
    }
    // A collapsing step: stopped with the place of the smallest step (every rank has the same
    // global step). Only rigid bodies at the start: the first finite step is the reference.
    if (!(s_.first_stable_dt < 1e299))
      s_.first_stable_dt = s_.stable_dt;
    if (c_.integrator.minimum_step_fraction() > 0 &&
        s_.stable_dt < c_.integrator.minimum_step_fraction() * s_.first_stable_dt)
      throw Instability(collapsed_step_message());
  }

  bool
  ExplicitStep::topology()
  {
    // 4b. Conversion (rare, collective): after the force of this step, before the kick, so
    // that stresses, history and d all belong to the end of the step.
    if (convert_now_)
      {
        const auto timer = c_.times.scope(Phase::topology);
        convert_(to_convert_); // (the flags are reset by the next internal_forces())
      }
    // 4c. Bond failure (collective on check steps), also after the force of this step: the
    // bonds are judged by this step's values; rows rebuilt, F reset to the new rows.
    if (!c_.bonds.is_check_step(s_.step))
      return false;
    const auto timer            = c_.times.scope(Phase::topology);
    const auto [broken, freed] = c_.bonds.update(c_.discretization, c_.particles, c_.spg, bond_values_);
    traffic_.add(base::Traffic::bonds, c_.bonds.bytes_sent());
    if (broken + freed == 0)
      return false;
    // The kick uses the forces of the new stencils: df = f_new - f_old where the changed rows
    // reach; the kick's kinetic energy (product form) sees it at once, booked as bond energy.
    if (df_.get_partitioner() != c_.discretization.partitioner())
      c_.discretization.initialize_vector(df_);
    df_                         = 0;
    const auto [a_rows, g_rows] = c_.particles.take_rebuilt_rows();
    const double w              = c_.spg.refresh_forces(s_.d, df_, a_rows, g_rows);
    df_.compress(VectorOperation::add);
    traffic_.add(base::Traffic::ghost_sums, sizeof(double) * df_.get_partitioner()->n_ghost_indices());
    s_.f += df_;
    c_.energy.book_bond_change(df_, s_.v, s_.dt, w);
    return true;
  }

  void
  ExplicitStep::kick(const bool last)
  {
    const auto timer = c_.times.scope(Phase::kick);
    s_.dt_next       = last ? s_.dt : c_.integrator.next_dt(s_.stable_dt, s_.t);
    c_.integrator.kick(s_.t, s_.dt, s_.dt_next, s_.f, s_.f_ext, s_.mass, s_.d, c_.conditions, s_.v, s_.v_now,
                       c_.energy.kick_terms());
  }

  std::string
  ExplicitStep::non_finite_source() const
  {
    for (const auto &m : Utilities::MPI::all_gather(comm_, c_.conditions.non_finite_report(s_.t)))
      if (!m.empty())
        return "; " + m;
    return "";
  }

  std::string
  ExplicitStep::collapsed_step_message() const
  {
    // The element or particle of this rank with the smallest own step, then of all ranks; ties
    // go to elements before particles, then to the smaller coarse cell id or global particle id, so
    // the answer does not depend on the partition.
    double             best = 1e300;
    unsigned long long kind = 2, id = 0;
    std::string        place;
    for (unsigned int e = 0; e < c_.hex.n_local_elements(); ++e)
      if (c_.hex.element_stable_dt(e) < best || (c_.hex.element_stable_dt(e) == best && c_.hex.cell_id(e) < id))
        {
          best  = c_.hex.element_stable_dt(e);
          kind  = 0;
          id    = c_.hex.cell_id(e);
          place = c_.hex.describe(e, s_.d);
        }
    if (c_.spg.active() && c_.spg.n_owned() > 0 && s_.particle_dt < best)
      {
        const unsigned int i = c_.spg.smallest_step_particle();
        best                 = s_.particle_dt;
        kind                 = 1;
        id                   = c_.particles.global_id(i);
        place                = c_.spg.describe(i);
      }
    std::ostringstream local;
    local << std::setprecision(17) << best << " " << kind << " " << id << " " << place;
    double             smallest  = 1e300;
    unsigned long long best_kind = 3, best_id = 0;
    std::string        where;
    for (const auto &text : Utilities::MPI::all_gather(comm_, local.str()))
      {
        std::istringstream in(text);
        double             dt = 1e300;
        unsigned long long k = 2, i = 0;
        in >> dt >> k >> i;
        if (dt < smallest || (dt == smallest && (k < best_kind || (k == best_kind && i < best_id))))
          {
            smallest  = dt;
            best_kind = k;
            best_id   = i;
            std::string rest;
            std::getline(in >> std::ws, rest);
            where = rest;
          }
      }
    std::ostringstream out;
    out << std::setprecision(6) << "step " << s_.step << ", t = " << s_.t << " s: the stable step " << s_.stable_dt
        << " s fell below " << c_.integrator.minimum_step_fraction() << " of the first step " << s_.first_stable_dt
        << " s (J - Time integration/minimum step fraction); smallest step " << smallest << " s in " << where;
    return out.str();
  }
} // namespace shard
