// SPDX-License-Identifier: LGPL-2.1-or-later
#include <shard/base/binary_archive.h>
#include <shard/base/function.h>
#include <shard/base/sections.h>
#include <shard/base/version.h>
#include <shard/base/plot.h>
#include <shard/base/parallel.h>
#include <shard/base/progress.h>
#include <shard/coupling/element_converter.h>
#include <shard/output/run_summary.h>
#include <shard/simulation/simulation.h>

#include <deal.II/base/mpi.h>

#include <array>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iomanip>
#include <iostream>
#include <sstream>
#include <unordered_map>

#include <sys/resource.h>
#ifdef __GLIBC__
#include <malloc.h>
#endif
#include <ctime>

namespace shard
{
  using namespace dealii;

  namespace
  {
    using Clock = std::chrono::steady_clock;
    using base::Phase;

    /// This process's resident set (bytes): now, its anonymous (heap, the model) and
    /// file-backed (shared-library pages: about 150 MB with Debian's deal.II, the same at any
    /// rank count) parts, and its peak.
    struct ProcessMemory
    {
      double resident = 0, anonymous = 0, file = 0, peak = 0;
    };

    ProcessMemory
    process_memory()
    {
      ProcessMemory m;
      std::ifstream status("/proc/self/status");
      std::string   key;
      double        kb = 0;
      while (status >> key)
        if (key == "VmRSS:" || key == "RssAnon:" || key == "RssFile:" || key == "VmHWM:")
          {
            status >> kb;
            (key == "VmRSS:" ? m.resident : key == "RssAnon:" ? m.anonymous : key == "VmHWM:" ? m.peak : m.file) =
              1024. * kb;
          }
      // ru_maxrss, or VmHWM if larger: the kernel updates ru_maxrss's high-water mark lazily, so
      // it can lag the present resident set by a few pages.
      rusage usage{};
      getrusage(RUSAGE_SELF, &usage);
      m.peak = std::max(m.peak, 1024. * usage.ru_maxrss);
      return m;
    }

    /// Per name, the value of every rank; @p by_rank holds per rank the values in the order of @p names.
    template <typename Names>
    std::vector<std::pair<std::string, std::vector<double>>>
    per_rank(const Names &names, const std::vector<std::vector<double>> &by_rank)
    {
      std::vector<std::pair<std::string, std::vector<double>>> out;
      for (unsigned int k = 0; k < names.size(); ++k)
        {
          out.emplace_back(names[k], std::vector<double>());
          for (const auto &r : by_rank)
            out.back().second.push_back(r[k]);
        }
      return out;
    }
  } // namespace


  Simulation::Simulation(MPI_Comm comm)
    : comm_(comm)
    , discretization_(comm)
    , bonds_(materials_)
    , explicit_step_(comm,
                     {discretization_, particles_, bonds_, conversion_, contact_, hex_, spg_, conditions_, integrator_,
                      energy_, times_},
                     state_, [this](const std::vector<unsigned int> &elements) { convert(elements); })
  {}

  bool
  Simulation::declare_parameters(ParameterHandler &prm)
  {
    if (!first_declaration())
      return false;
    prm.enter_subsection(sections::simulation);
    prm.add_parameter("title", title_, "A one-line description of the scene, copied into summary.json.");
    prm.leave_subsection();
    return true;
  }

  void
  Simulation::check_parameters(const base::PrmSource &) const
  {}

  void
  Simulation::read(const base::PrmSource &source)
  {
    source_ = source;
    base::read_parameters(prm_,
                          {this, &discretization_, &materials_, &particles_, &bonds_, &conversion_, &contact_, &hex_,
                           &spg_, &conditions_, &integrator_, &output_, &quantities_, &checkpoint_},
                          source_);
  }

  void
  Simulation::print_parameters(std::ostream &out) const
  {
    prm_.print_parameters(out, ParameterHandler::PRM | ParameterHandler::KeepDeclarationOrder);
  }

  void
  Simulation::check_rigid_bodies() const
  {
    const auto &bodies = discretization_.bodies();
    std::vector<bool> converted(bodies.size(), false);
    for (const auto &cell : discretization_.dof_handler().active_cell_iterators())
      if (cell->is_locally_owned() && conversion_.converted_cells()[cell->active_cell_index()])
        converted[cell->material_id()] = true;
    const auto &adaptive_bodies = conversion_.adaptive_bodies();
    const auto  particle_bodies = particles_.body_names();
    for (unsigned int b = 0; b < bodies.size(); ++b)
      {
        if (!materials_.get(bodies[b].material).rigid())
          continue;
        const bool adaptive  = std::count(adaptive_bodies.begin(), adaptive_bodies.end(), b);
        const bool any       = Utilities::MPI::max(converted[b] ? 1u : 0u, comm_) > 0;
        const bool particles = std::count(particle_bodies.begin(), particle_bodies.end(), bodies[b].name);
        if (any || adaptive)
          source_.fail(particles ? sections::particles + "/bodies" :
                                   sections::conversion + (any ? "/regions" : "/adaptive bodies"),
                       bodies[b].name,
                       "body '" + bodies[b].name + "' has the rigid material '" + bodies[b].material +
                         "': a rigid body stays FE (no particles, no conversion, no conversion region).");
      }
  }

  void
  Simulation::prepare()
  {
    const auto   start     = Clock::now();
    const double cpu_start = base::PhaseTimes::thread_cpu_time();
    // The partition is weighted by the particles of the set-up conversion (B - Mesh/particle
    // weight); rank 0 computes it on the serial mesh. (Also on a restart: the partition of the
    // set-up, as in the run that wrote the checkpoint.)
    discretization_.prepare(source_, [this](const mesh::Discretization &d) {
      return conversion_.converted_at_setup(d, particles_.body_names(), source_);
    });
    imbalance_before_ = discretization_.imbalance_by_count();
    for (const auto &b : discretization_.bodies())
      if (!materials_.has(b.material))
        source_.fail(sections::mesh + "/" + b.name + "/material", b.material,
                     "no such material in 'C - Materials/material names'.");
    materials_.prepare();
    // Particles first: their two-hop stencil widens the ghost set, which changes local indices.
    conversion_.prepare(discretization_, particles_.body_names(), source_);
    check_rigid_bodies();
    checkpoint_.prepare(discretization_, output_.directory(), fingerprint(), source_);
    if (checkpoint_.restarting())
      restore_topology();
    particles_.prepare(discretization_, conversion_.converted_cells(), conditions_.faces(), source_);
    hex_.prepare(discretization_, materials_, conversion_.converted_cells());
    spg_.prepare(discretization_, particles_, materials_);
    bonds_.prepare(particles_, spg_, source_);
    conditions_.prepare(discretization_, source_);
    output_.prepare(discretization_, hex_, spg_);
    quantities_.prepare(discretization_, hex_, conditions_, spg_, source_);
    fragments_.prepare(discretization_, hex_, particles_);

    for (auto *vec : state_.vectors())
      discretization_.initialize_vector(*vec);
    // The FE lumped mass of every cell: particles at nodes keep it (formulation.md section 7).
    hex_.add_lumped_mass(state_.mass);
    state_.mass.compress(VectorOperation::add);
    state_.mass.update_ghost_values();
    contact_.prepare(discretization_, materials_, particles_, conversion_.converted_cells(), state_.mass, source_);
    {
      // The energy scale M c^2 of the model (total mass, fastest initial wave speed): a floor of
      // the energy error's reference, so that round-off in a model at rest is not reported as an
      // error of 1 (the reference is then round-off too).
      double wave_speed = 0;
      for (const auto &b : discretization_.bodies())
        if (const double c = materials_.get(b.material).initial_wave_speed(); std::isfinite(c))
          wave_speed = std::max(wave_speed, c);
      double mass = 0;
      for (unsigned int i = 0; i < state_.mass.locally_owned_size(); i += 3)
        mass += state_.mass.local_element(i);
      energy_.set_floor(1e-14 * Utilities::MPI::sum(mass, comm_) * wave_speed * wave_speed);
    }

    // Initial velocity of each body at its nodes.
    const auto &X = discretization_.reference_positions();
    std::string non_finite; // "body\nwhere" of the first node with a non-finite initial velocity
    for (unsigned int k = 0; k < discretization_.bodies().size(); ++k)
      {
        const auto     velocity = base::parse_vector_function(discretization_.bodies()[k].initial_velocity, false);
        Vector<double> value(3);
        for (const unsigned int j : discretization_.body_nodes(k))
          {
            const Point<3> x(X.local_element(j), X.local_element(j + 1), X.local_element(j + 2));
            velocity->vector_value(x, value);
            for (unsigned int i = 0; i < 3; ++i)
              state_.v.local_element(j + i) = value[i];
            if (non_finite.empty() && !(std::isfinite(value[0]) && std::isfinite(value[1]) && std::isfinite(value[2])))
              non_finite = discretization_.bodies()[k].name + "\n" + base::non_finite_at(*velocity, {x}, 0.);
          }
      }
    for (const auto &m : Utilities::MPI::all_gather(comm_, non_finite))
      if (!m.empty())
        {
          const auto name = m.substr(0, m.find('\n'));
          const auto body = discretization_.body_index(name);
          source_.fail(sections::mesh + "/" + name + "/initial velocity", discretization_.bodies()[body].initial_velocity,
                       "is not finite: " + m.substr(m.find('\n') + 1) + ".");
        }
    measure_partition();
    if (checkpoint_.restarting())
      restore_state();
#ifdef __GLIBC__
    // The set-up's temporaries (body meshes, gathered tables) are freed, but glibc keeps the
    // pages resident below live blocks: give them back, so the resident set of the run is what
    // it holds (summary.json memory_by_rank_bytes; the peak stays what the set-up reached).
    malloc_trim(0);
#endif
    times_.add(Phase::setup, std::chrono::duration<double>(Clock::now() - start).count(),
               base::PhaseTimes::thread_cpu_time() - cpu_start);
  }

  void
  Simulation::measure_partition()
  {
    rank_elements_  = Utilities::MPI::all_gather(comm_, double(hex_.n_local_elements()));
    rank_particles_ = Utilities::MPI::all_gather(comm_, double(particles_.active() ? particles_.n_owned() : 0));
    const double w  = discretization_.particle_weight() > 0 ? discretization_.particle_weight() :
                                                                      mesh::Discretization::default_particle_weight;
    double       largest = 0, total = 0;
    for (unsigned int r = 0; r < rank_elements_.size(); ++r)
      {
        const double work = rank_elements_[r] + w * rank_particles_[r];
        largest           = std::max(largest, work);
        total += work;
      }
    imbalance_ = total > 0 ? largest * rank_elements_.size() / total : 1;
  }

  RunResult
  Simulation::run()
  {
    const auto start = Clock::now();
    RunResult  result{"completed", "", 0};
    times_.reset_cpu();
    const bool restarted = state_.step > 0;
    if (!this->start(result))
      return result; // step 0 failed its checks: nothing written
    open_output(restarted);
    // A restart from the checkpoint of the last step (or past a smaller end): no step is left,
    // and the run ends where the straight one did.
    bool stop = restarted && at_end();
    if (stop)
      record_status(result);
    try
      {
        while (!stop)
          {
            explicit_step_.step_size();       // 1
            explicit_step_.drift();           // 2
            explicit_step_.exchange();        // 3
            explicit_step_.internal_forces(); // 5, 6
            explicit_step_.loads();           // 7
            explicit_step_.accumulate();      // 8
            if (explicit_step_.topology())    // 4b conversion, 4c bond failure
              fragments_stale_ = true;        // prepared again at the next fragment output
            const bool last = at_end();
            explicit_step_.kick(last);        // 9
            stop = record_step(last, result); // 10
          }
      }
    catch (const Instability &e)
      {
        result = {"unstable", e.what(), 3};
      }
    finish(result, std::chrono::duration<double>(Clock::now() - start).count());
    return result;
  }

  bool
  Simulation::at_end() const
  {
    return state_.t >= integrator_.end_time() * (1 - 1e-12) ||
           (integrator_.max_steps() > 0 && state_.step >= integrator_.max_steps());
  }

  void
  Simulation::record_status(RunResult &result) const
  {
    if (integrator_.max_steps() > 0 && state_.step >= integrator_.max_steps() &&
        state_.t < integrator_.end_time() * (1 - 1e-12))
      result.status = "max steps reached";
  }

  bool
  Simulation::start(RunResult &result)
  {
    const unsigned int rank      = Utilities::MPI::this_mpi_process(comm_);
    const bool         restarted = state_.step > 0;
    if (rank == 0 && !restarted)
      std::cerr << "shard: " << Utilities::MPI::n_mpi_processes(comm_) << " MPI rank(s) x " << base::n_threads()
                << " thread(s) per rank\n";
    if (rank == 0 && rank_elements_.size() > 1 && particles_.active())
      {
        std::fprintf(stderr, "partition: elements per rank");
        for (const double n : rank_elements_)
          std::fprintf(stderr, " %.0f", n);
        std::fprintf(stderr, ", particles per rank");
        for (const double n : rank_particles_)
          std::fprintf(stderr, " %.0f", n);
        std::fprintf(stderr, "; work imbalance (max/mean) %.3f", imbalance_);
        if (imbalance_before_ > 0)
          std::fprintf(stderr, " (cell-count partition: %.3f)", imbalance_before_);
        std::fprintf(stderr, "\n");
      }

    // Initial state: kinetic energy of the input, then the kinematic conditions at t = 0
    // (a restart has it from the checkpoint). Nothing is written before step 0 has passed its
    // checks: a run that stops there leaves an earlier run's results in the directory untouched.
    integrator_.rigid_bodies().prepare(discretization_, materials_, state_.mass);
    if (restarted)
      return true;
    auto  &s  = state_;
    double ke = 0;
    for (unsigned int i = 0; i < s.v.locally_owned_size(); ++i)
      ke += 0.5 * s.mass.local_element(i) * s.v.local_element(i) * s.v.local_element(i);
    energy_.set_initial_kinetic(Utilities::MPI::sum(ke, comm_));
    initial_max_speed_ = fastest_node(s.v).speed;
    energy_.kick_terms().boundary_work += conditions_.apply_initial(s.d, s.mass, s.v);
    s.stable_dt       = std::min(hex_.initial_stable_dt(), spg_.initial_stable_dt());
    s.first_stable_dt = Utilities::MPI::min(s.stable_dt, comm_);
    if (!(s.first_stable_dt < 1e299) && !(integrator_.fixed_time_step() > 0))
      source_.fail(sections::time_integration + "/fixed time step", "0",
                   "no element or particle limits the step (every body is rigid): set a fixed time step > 0. "
                   "Unit: s.");
    s.f     = 0;
    s.f_ext = 0;
    conditions_.add_external_forces(0., s.f_ext);
    s.f += s.f_ext;
    s.dt_next = integrator_.next_dt(s.stable_dt, 0.);
    integrator_.kick(0., 0., s.dt_next, s.f, s.f_ext, s.mass, s.d, conditions_, s.v, s.v_now, energy_.kick_terms());
    s.d.update_ghost_values();
    s.v_now.update_ghost_values();
    try
      {
        record(); // the row waits in the history table until history.csv is opened
      }
    catch (const Instability &e)
      {
        result = {"unstable", e.what(), 3, false};
        return false;
      }
    return true;
  }

  void
  Simulation::open_output(const bool restarted)
  {
    // From here the run owns its output directory.
    output_.create_directory();
    if (Utilities::MPI::this_mpi_process(comm_) == 0)
      {
        // A restart keeps the rows up to the checkpoint (cut back in restore_state()) and appends.
        history_.open(output_.directory() + "/history.csv", restarted);
        std::ofstream used(output_.directory() + "/parameters.prm");
        prm_.print_parameters(used, ParameterHandler::ShortPRM | ParameterHandler::KeepDeclarationOrder);
        materials_.write_resolved_parameters(output_.directory() + "/generated_parameters.prm");
      }
    if (!restarted)
      {
        output_.write(0., physical_displacement(), state_.v_now);
        write_fragments();
        next_output_ = output_.interval();
      }
    progress_.last       = Clock::now();
    progress_.loop_start = progress_.last;
    progress_.start_time = state_.t;
  }

  bool
  Simulation::record_step(const bool last, RunResult &result)
  {
    const auto timer = times_.scope(Phase::record); // outside the step timings of phases 1-9
    auto      &s     = state_;
    if (s.step % output_.history_interval() == 0 || last)
      record();
    if (last || (output_.interval() > 0 && s.t >= next_output_ * (1 - 1e-12)))
      {
        s.d.update_ghost_values();
        s.v_now.update_ghost_values();
        output_.write(s.t, physical_displacement(), s.v_now);
        write_fragments();
        while (next_output_ <= s.t * (1 + 1e-12) && output_.interval() > 0)
          next_output_ += output_.interval();
      }
    const double since = std::chrono::duration<double>(Clock::now() - progress_.last).count();
    if (Utilities::MPI::this_mpi_process(comm_) == 0 && output_.progress_interval() > 0 &&
        (since >= output_.progress_interval() || last))
      {
        const double end = integrator_.end_time();
        progress_.last   = Clock::now();
        progress_.pace.add(std::chrono::duration<double>(progress_.last - progress_.loop_start).count(), s.t);
        const double eta = progress_.pace.remaining(end, progress_.start_time);
        std::fprintf(stderr,
                     "step %8u  t = %.4e s of %.4e s (%5.1f %%)  dt = %.3e s  energy error %+.2e  "
                     "ETA %.0f s\n",
                     s.step, s.t, end, 100. * s.t / end, s.dt, energy_.error(), eta);
        history_.flush();
      }
    // Checkpoint: after the record, so that the tables it cuts back to hold this step.
    if (checkpoint_.is_due(s.step))
      write_checkpoint();
    record_status(result);
    return last;
  }

  void
  Simulation::finish(const RunResult &result, const double wall_time)
  {
    history_.close();
    const unsigned int rank = Utilities::MPI::this_mpi_process(comm_);
    if (rank == 0 && !last_fragments_.empty())
      write_fragment_statistics();
    if (rank == 0 && !last_fragments_.empty() && output_.fragment_plots())
      {
        const std::string warning = base::run_plot_script(
          "plot_fragments.py", {output_.directory(), output_.directory() + "/fragments.png"});
        if (!warning.empty())
          std::cerr << "shard: warning: " << warning << "\n";
      }
    // Element-steps and particle-steps actually computed (conversion changes the counts).
    {
      const double local[2] = {explicit_step_.element_steps(), explicit_step_.particle_steps()};
      Utilities::MPI::sum(ArrayView<const double>(local, 2), comm_, ArrayView<double>(work_steps_.data(), 2));
    }
    const auto max_time = times_.max_wall(comm_);
    write_summary(result, wall_time, max_time);
    if (rank == 0)
      base::PhaseTimes::print_table(stderr, max_time, base::n_threads(), work_steps_[0], work_steps_[1]);
  }

  void
  Simulation::write_fragment_statistics() const
  {
    // Fragment statistics of the last output: by mass, largest first, with the cumulative
    // mass fraction, the speed, size, shape and the debris classification
    // (doc/manual/failure.md, "Fragments").
    auto sorted = last_fragments_;
    std::stable_sort(sorted.begin(), sorted.end(),
                     [](const output::Fragment &a, const output::Fragment &b) { return a.mass > b.mass; });
    double total = 0;
    for (const auto &f : sorted)
      total += f.mass;
    std::ofstream out(output_.directory() + "/fragment_statistics.csv");
    out << "time,rank_by_mass,fragment,nodes,particles,mass,cumulative_mass_fraction,speed,kinetic_energy,"
           "body,volume,equivalent_diameter,aspect_ratio,debris,dust,cone_angle,x0,y0,z0\n";
    double cumulative = 0;
    char   row[512], shape[256];
    for (std::size_t k = 0; k < sorted.size(); ++k)
      {
        const auto &f = sorted[k];
        cumulative += f.mass;
        std::snprintf(row, sizeof(row), "%.10e,%zu,%llu,%llu,%llu,%.16e,%.16e,%.10e,%.10e,", last_fragments_time_,
                      k + 1, f.id, f.nodes, f.particles, f.mass, cumulative / total,
                      std::hypot(f.velocity[0], f.velocity[1], f.velocity[2]), f.kinetic_energy);
        std::snprintf(shape, sizeof(shape), ",%.16e,%.16e,%.16e,%d,%d,%.16e,%.16e,%.16e,%.16e\n", f.volume,
                      f.equivalent_diameter, f.aspect_ratio, int(f.debris), int(f.dust), f.cone_angle, f.origin[0],
                      f.origin[1], f.origin[2]);
        out << row << discretization_.bodies()[f.body].name << shape;
      }
  }

  void
  Simulation::record()
  {
    // One reduction of the energy terms and momentum (EnergyBalance): the hourglass column holds
    // the FE hourglass work plus the particle stabilization energy; the internal energy includes
    // the elastic energy changed by conversions and the contact energy.
    const auto  e = energy_.reduce({contact_.energy(), contact_.friction_energy(), contact_.stored_energy(),
                                    contact_.damping_energy()},
                                  comm_);
    const auto &s = state_;
    const auto  q = quantities_.evaluate(physical_displacement(), s.v_now, state_.mass, s.t);
    if (q_final_.empty())
      {
        q_min_ = q;
        q_max_ = q;
      }
    for (unsigned int i = 0; i < q.size(); ++i)
      {
        q_min_[i] = std::min(q_min_[i], q[i]);
        q_max_[i] = std::max(q_max_[i], q[i]);
      }
    q_final_ = q;

    // The columns of history.csv (doc/manual/time_loop.md, "Energy balance"), then the quantities.
    output::HistoryTable::Row row = {{"time", s.t},
                                     {"step", double(s.step), true},
                                     {"dt", s.dt_next},
                                     {"kinetic_energy", e.kinetic},
                                     {"internal_energy", e.internal},
                                     {"hourglass_energy", e.hourglass},
                                     {"external_work", e.external},
                                     {"boundary_work", e.boundary},
                                     {"filter_work", e.filter},
                                     {"conversion_energy", e.conversion},
                                     {"bond_energy", e.bond},
                                     {"energy_error", e.error},
                                     {"momentum_x", e.momentum[0]},
                                     {"momentum_y", e.momentum[1]},
                                     {"momentum_z", e.momentum[2]},
                                     {"converted_elements", double(conversion_.n_converted()), true},
                                     {"broken_bonds", double(bonds_.n_broken()), true},
                                     {"free_particles", double(bonds_.n_free()), true},
                                     {"contact_energy", e.contact},
                                     {"friction_energy", e.friction},
                                     {"contact_wall_force", Utilities::MPI::sum(contact_.wall_force(), comm_)},
                                     {"contact_stored_energy", e.stored},
                                     {"contact_lost_energy", e.contact_lost()},
                                     {"contact_damping_energy", e.damping}};
    const std::size_t n_energy_columns = row.size();
    const auto       &names            = quantities_.names();
    for (unsigned int i = 0; i < q.size(); ++i)
      row.push_back({names[i], q[i]});
    if (Utilities::MPI::this_mpi_process(comm_) == 0)
      history_.add(row);

    const auto g6 = [](const double x) {
      std::ostringstream out;
      out << std::setprecision(6) << x;
      return out.str();
    };
    const std::string when = "step " + std::to_string(s.step) + ", t = " + g6(s.t) + " s: ";
    if (!std::isfinite(e.kinetic) || !std::isfinite(e.internal))
      throw Instability(when + "non-finite energy (kinetic " + g6(e.kinetic) + " J, internal " +
                            g6(e.internal) + " J)" + explicit_step_.non_finite_source());
    // Every other column of the row: a run never ends with a non-finite value in its history.
    if (const int k = output::HistoryTable::first_non_finite(row); k >= 0)
      {
        if (std::size_t(k) < n_energy_columns)
          throw Instability(when + row[k].name + " is " + g6(row[k].value) + explicit_step_.non_finite_source());
        throw Instability(when + "quantity '" + row[k].name + "' (L - Quantities/quantities) is " +
                              g6(row[k].value));
      }
    if (std::abs(e.error) > integrator_.energy_error_limit())
      throw Instability(when + "energy error " + g6(e.error) + " exceeds the limit " +
                            g6(integrator_.energy_error_limit()) + " (kinetic " + g6(e.kinetic) + " J, internal " +
                            g6(e.internal) + " J, external work " + g6(e.external) + " J, boundary work " +
                            g6(e.boundary) + " J, initial kinetic " + g6(energy_.initial_kinetic()) + " J); " +
                            fastest_node(s.v_now).describe());
  }

  std::string
  Simulation::FastestNode::describe() const
  {
    std::ostringstream out;
    out << std::setprecision(6) << "fastest " << (particle ? "particle " : "node ") << id << " of body '" << body
        << "' at (" << position[0] << ", " << position[1] << ", " << position[2] << ") m: speed " << speed
        << " m/s (largest initial speed " << initial_speed << " m/s)";
    return out.str();
  }

  Simulation::FastestNode
  Simulation::fastest_node(const mesh::Vector &v) const
  {
    // Owned nodes of every body; the fastest of this rank, then of all ranks (every rank gets
    // the same answer; ties go to the lowest rank).
    const auto         &X = discretization_.reference_positions();
    std::array<double, 6> best{{-1, 0, 0, 0, 0, 0}}; // speed, body, global node id, x, y, z
    for (unsigned int b = 0; b < discretization_.bodies().size(); ++b)
      for (const unsigned int i : discretization_.body_nodes(b))
        {
          const double s = std::sqrt(v.local_element(i) * v.local_element(i) +
                                     v.local_element(i + 1) * v.local_element(i + 1) +
                                     v.local_element(i + 2) * v.local_element(i + 2));
          if (s > best[0])
            best = {{s, double(b), double(v.get_partitioner()->local_to_global(i) / 3),
                     X.local_element(i) + state_.d.local_element(i), X.local_element(i + 1) + state_.d.local_element(i + 1),
                     X.local_element(i + 2) + state_.d.local_element(i + 2)}};
        }
    for (const auto &other : Utilities::MPI::all_gather(comm_, best))
      if (other[0] > best[0] || (other[0] == best[0] && other[2] < best[2]))
        best = other;
    FastestNode r;
    r.speed         = std::max(best[0], 0.);
    r.initial_speed = initial_max_speed_;
    const auto b    = static_cast<unsigned int>(best[1]);
    r.body          = b < discretization_.bodies().size() ? discretization_.bodies()[b].name : "";
    r.particle      = particles_.is_particle_body(b);
    r.id            = static_cast<unsigned long long>(best[2]);
    r.position      = {{best[3], best[4], best[5]}};
    return r;
  }


  void
  Simulation::convert(const std::vector<unsigned int> &elements)
  {
    const double old_stabilization = Utilities::MPI::sum(energy_.stabilization(), comm_);
    coupling::ElementConverter converter(
      {conversion_, discretization_, materials_, particles_, bonds_, hex_, spg_, conditions_, source_});
    const auto r = converter.convert(elements, state_.vectors(), state_.d, state_.v);
    if (r.added == 0)
      return;
    energy_.set_stabilization(r.stabilization);
    // Components that hold local indices or particle lists follow the new layout.
    physical_step_ = ~0u;
    quantities_.prepare(discretization_, hex_, conditions_, spg_, source_);
    fragments_.prepare(discretization_, hex_, particles_);
    contact_.prepare(discretization_, materials_, particles_, conversion_.converted_cells(), state_.mass, source_);
    state_.stable_dt = std::min(state_.stable_dt, spg_.current_stable_dt());

    // The change of the stored elastic energy and the jump of the stabilization energy are a
    // source of the balance; the elastic part is also internal energy (booked on rank 0).
    const double elastic = r.elastic_after - r.elastic_before;
    const double change  = elastic + Utilities::MPI::sum(energy_.stabilization(), comm_) - old_stabilization;
    energy_.book_conversion(change, Utilities::MPI::this_mpi_process(comm_) == 0 ? elastic : 0.);
    if (Utilities::MPI::this_mpi_process(comm_) == 0)
      std::fprintf(stderr,
                   "step %8u  conversion: %llu cells (%llu converted in all), %llu particles; energy change "
                   "%.3e J (elastic %.3e J), %.3e J in all\n",
                   state_.step, r.added, conversion_.n_converted(), particles_.n_global(), change, elastic,
                   energy_.conversion_energy());
  }

  const mesh::Vector &
  Simulation::physical_displacement()
  {
    if (!spg_.active() || physical_step_ == state_.step)
      return spg_.active() ? state_.d_phys : state_.d;
    physical_step_ = state_.step;
    state_.d_phys        = state_.d;
    spg_.physical_displacement(state_.d_phys);
    state_.d_phys.update_ghost_values();
    return state_.d_phys;
  }

  void
  Simulation::write_fragments()
  {
    if (!particles_.active())
      return;
    if (fragments_stale_)
      fragments_.prepare(discretization_, hex_, particles_);
    fragments_stale_     = false;
    last_fragments_      = fragments_.compute(physical_displacement(), state_.v_now, state_.mass);
    last_fragments_time_ = state_.t;
    output::classify(last_fragments_, output_.dust_particles(), output_.debris_axis());
    if (Utilities::MPI::this_mpi_process(comm_) != 0)
      return;
    const std::string path  = output_.directory() + "/fragments.csv";
    const bool        first = !fragments_started_;
    std::ofstream     out(path, first ? std::ios::trunc : std::ios::app);
    if (first)
      out << "time,fragment,nodes,particles,mass,x,y,z,vx,vy,vz,kinetic_energy\n";
    fragments_started_ = true;
    char row[512];
    for (const auto &f : last_fragments_)
      {
        std::snprintf(row, sizeof(row), "%.10e,%llu,%llu,%llu,%.16e,%.10e,%.10e,%.10e,%.10e,%.10e,%.10e,%.10e\n", state_.t,
                      f.id, f.nodes, f.particles, f.mass, f.centre[0], f.centre[1], f.centre[2], f.velocity[0],
                      f.velocity[1], f.velocity[2], f.kinetic_energy);
        out << row;
      }
  }

  void
  Simulation::write_summary(const RunResult &result, const double wall_time,
                            const base::PhaseTimes::Times &max_time) const
  {
    // Memory: solver-owned particle data and the distributed vectors of the time loop (summed
    // over ranks), peak resident set size (largest over ranks), and every rank's parts.
    const ProcessMemory process = process_memory();
    double vector_bytes = 0;
    for (auto *vec : const_cast<StepState &>(state_).vectors())
      vector_bytes += vec->memory_consumption();
    // The parts of this rank's memory, in the order of memory_names.
    const std::vector<std::string> memory_names{"mesh", "dof handler", "particles", "elements", "contact",
                                                "vectors", "resident at end", "anonymous at end",
                                                "file-backed at end", "peak resident"};
    const std::vector<double> memory_parts{
      double(discretization_.triangulation().memory_consumption()),
      double(discretization_.dof_handler().memory_consumption()),
      particles_.active() ? double(particles_.memory_consumption() + spg_.memory_consumption()) : 0.,
      double(hex_.memory_consumption()),
      contact_.memory_consumption(),
      vector_bytes,
      process.resident,
      process.anonymous,
      process.file,
      process.peak};
    double memory[2] = {memory_parts[2], vector_bytes};
    Utilities::MPI::sum(ArrayView<const double>(memory, 2), comm_, ArrayView<double>(memory, 2));
    const double element_bytes = Utilities::MPI::sum(memory_parts[3], comm_);
    const double n_hexes       = Utilities::MPI::sum(double(hex_.n_local_elements()), comm_);
    const auto   rank_times = Utilities::MPI::all_gather(comm_, std::vector<double>(times_.wall().begin(), times_.wall().end()));
    const auto   rank_cpu   = Utilities::MPI::all_gather(comm_, std::vector<double>(times_.cpu().begin(), times_.cpu().end()));
    std::vector<double> traffic;
    for (unsigned int x = 0; x < base::Traffic::n_exchanges; ++x)
      traffic.push_back(explicit_step_.traffic().per_step(base::Traffic::Exchange(x)));
    const auto   rank_traffic = Utilities::MPI::all_gather(comm_, traffic);
    const auto   rank_memory  = Utilities::MPI::all_gather(comm_, memory_parts);
    const double peak_rss     = Utilities::MPI::max(memory_parts.back(), comm_);
    const auto   rank_known   = Utilities::MPI::all_gather(
      comm_, std::array<double, 3>{{double(particles_.broken_bonds().size()), double(particles_.free_particles().size()),
                                    double(particles_.table_rows())}});
    if (Utilities::MPI::this_mpi_process(comm_) != 0)
      return;
    output::RunSummary s;
    s.version        = std::string(version_string) + " (" + git_description + ")";
    s.title          = title_;
    s.parameter_file = source_.filename();
    s.status         = result.status;
    s.message        = result.message;
    s.steps          = state_.step;
    s.final_time     = state_.t;
    s.last_dt        = state_.dt;
    s.wall_time      = wall_time + max_time[0];
    s.n_elements     = discretization_.n_elements();
    s.n_particles    = particles_.n_global();
    s.n_converted_elements = conversion_.n_converted();
    s.conversion_events    = conversion_.n_events();
    s.conversion_energy    = energy_.conversion_energy();
    s.broken_bonds         = bonds_.n_broken();
    s.free_particles       = bonds_.n_free();
    s.contact_rebuilds     = contact_.n_rebuilds();
    for (const auto &known : rank_known)
      {
        s.known_broken_bonds_by_rank.push_back(known[0]);
        s.known_free_particles_by_rank.push_back(known[1]);
        if (particles_.active())
          s.particle_table_rows_by_rank.push_back(known[2]);
      }
    if (!last_fragments_.empty())
      {
        double total = 0, largest = 0;
        for (const auto &f : last_fragments_)
          total += f.mass, largest = std::max(largest, f.mass);
        s.fragments.count        = last_fragments_.size();
        s.fragments.total_mass   = total;
        s.fragments.largest_mass = largest;
        s.fragments.json =
          output::summary_json(last_fragments_, last_fragments_time_, output_.dust_particles(), output_.debris_axis());
      }
    s.correction_iterations = spg_.correction_solve().iterations;
    s.n_mpi_ranks           = Utilities::MPI::n_mpi_processes(comm_);
    s.n_threads             = base::n_threads();
    s.energy_error          = energy_.error();
    s.max_abs_energy_error  = energy_.max_error();
    const double element_steps = work_steps_[0], particle_steps = work_steps_[1];
    s.element_steps_per_s      = max_time[5] > 0 ? element_steps / max_time[5] : 0;
    s.us_per_element_step      = element_steps > 0 ? 1e6 * max_time[5] / element_steps : 0;
    const double n_particles   = particles_.n_global();
    s.particle_steps_per_s     = max_time[6] > 0 ? particle_steps / max_time[6] : 0;
    s.us_per_particle_step     = particle_steps > 0 ? 1e6 * max_time[6] / particle_steps : 0;
    s.particle_bytes           = memory[0];
    s.bytes_per_particle       = n_particles > 0 ? memory[0] / n_particles : 0;
    s.n_dofs                   = state_.d.size();
    s.vector_bytes             = memory[1];
    s.vector_bytes_per_dof     = state_.d.size() > 0 ? memory[1] / state_.d.size() : 0;
    s.element_bytes            = element_bytes;
    s.bytes_per_element        = n_hexes > 0 ? element_bytes / n_hexes : 0;
    s.peak_rss_bytes           = peak_rss;
    s.partition                = {discretization_.particle_weight(), rank_elements_, rank_particles_, imbalance_,
                                  imbalance_before_};
    s.phase_time_by_rank       = rank_times;
    s.phase_cpu_time_by_rank   = rank_cpu;
    for (unsigned int p = 0; p < base::PhaseTimes::n_phases; ++p)
      s.phase_time.emplace_back(base::PhaseTimes::names()[p], max_time[p]);
    s.bytes_sent_per_step_by_rank = per_rank(base::Traffic::names(), rank_traffic);
    s.memory_by_rank              = per_rank(memory_names, rank_memory);
    const auto names = quantities_.names();
    for (unsigned int i = 0; i < names.size(); ++i)
      s.results.push_back({names[i], q_final_[i], q_min_[i], q_max_[i]});
    s.history_file   = output_.directory() + "/history.csv";
    s.field_file     = output_.series_path();
    s.parameter_copy = output_.directory() + "/parameters.prm";
    output::write_run_summary_file(s, output_.directory() + "/summary.json");
  }

} // namespace shard
