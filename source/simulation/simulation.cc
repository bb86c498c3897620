// SPDX-License-Identifier: LGPL-2.1-or-later
#include <shard/base/binary_archive.h>
#include <shard/base/function.h>
#include <shard/base/version.h>
#include <shard/fe/hex_kernel.h>
#include <shard/base/plot.h>
#include <shard/base/parallel.h>
#include <shard/base/progress.h>
#include <shard/simulation/simulation.h>

#include <deal.II/base/mpi.h>

#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <iomanip>
#include <iostream>
#include <sstream>
#include <unordered_map>

#include <sys/resource.h>
#include <ctime>

namespace shard
{
  using namespace dealii;

  namespace
  {
    using Clock = std::chrono::steady_clock;

    /// Phases of the explicit step (doc/manual/time_loop.md); index = phase number.
    const char *const phase_names[11] = {"0 set-up",       "1 step size",  "2 drift",   "3 exchange",
                                         "4 topology",     "5 FE force",   "6 particle force",
                                         "7 loads",        "8 accumulate", "9 kick",    "10 record"};

    /// CPU time of the calling thread (s).
    double
    thread_cpu_time()
    {
      timespec t{};
      clock_gettime(CLOCK_THREAD_CPUTIME_ID, &t);
      return t.tv_sec + 1e-9 * t.tv_nsec;
    }

    /// CPU time of this rank's main thread per phase (phase_cpu_time_by_rank_s of summary.json;
    /// one Simulation per process runs at a time, reset at the start of Simulation::run()). On a
    /// shared machine it shows the work of a phase without the time the rank was descheduled
    /// (doc/performance.md, MPI scaling).
    std::array<double, 11> phase_cpu_time{};

    /// Adds the wall time of a scope to one phase (and its CPU time to phase_cpu_time).
    class PhaseTimer
    {
    public:
      PhaseTimer(std::array<double, 11> &times, const unsigned int phase)
        : times_(times)
        , phase_(phase)
        , start_(Clock::now())
        , cpu_start_(thread_cpu_time())
      {}
      ~PhaseTimer()
      {
        times_[phase_] += std::chrono::duration<double>(Clock::now() - start_).count();
        phase_cpu_time[phase_] += thread_cpu_time() - cpu_start_;
      }

    private:
      std::array<double, 11> &times_;
      unsigned int            phase_;
      Clock::time_point       start_;
      double                  cpu_start_;
    };

    std::string
    number(const double x)
    {
      if (!std::isfinite(x))
        return "null";
      std::ostringstream s;
      s << std::setprecision(10) << x;
      return s.str();
    }
  } // namespace

  namespace
  {
    /// The first @p bytes bytes of the file @p path (fewer if it is shorter; "" if absent).
    std::string
    file_head(const std::string &path, const unsigned long long bytes)
    {
      std::ifstream in(path, std::ios::binary);
      std::string   data(bytes, '\0');
      in.read(data.data(), static_cast<std::streamsize>(bytes));
      data.resize(in ? bytes : static_cast<std::size_t>(std::max<std::streamsize>(in.gcount(), 0)));
      return data;
    }
  } // namespace

  Simulation::Simulation(MPI_Comm comm)
    : comm_(comm)
    , discretization_(comm)
    , bonds_(materials_)
  {}

  bool
  Simulation::declare_parameters(ParameterHandler &prm)
  {
    if (declared_)
      return false;
    declared_ = true;
    prm.enter_subsection("A - Simulation");
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
          source_.fail(particles ? "E - Particles/bodies" : any ? "G - Conversion/regions" : "G - Conversion/adaptive bodies",
                       bodies[b].name,
                       "body '" + bodies[b].name + "' has the rigid material '" + bodies[b].material +
                         "': a rigid body stays FE (no particles, no conversion, no conversion region).");
      }
  }

  void
  Simulation::prepare()
  {
    const auto start = Clock::now();
    discretization_.prepare(source_);
    for (const auto &b : discretization_.bodies())
      if (!materials_.has(b.material))
        source_.fail("B - Mesh/" + b.name + "/material", b.material,
                     "no such material in 'C - Materials/material names'.");
    materials_.prepare();
    // Particles first: their two-hop stencil widens the ghost set, which changes local indices.
    conversion_.prepare(discretization_, particles_.body_names(), source_);
    check_rigid_bodies();
    // Cells weighted by their particles (B - Mesh/particle weight); the flags follow the new partition.
    // (Also on a restart: the partition of the set-up, as in the run that wrote the checkpoint.)
    if (conversion_.n_converted() > 0 && (imbalance_before_ = discretization_.repartition(conversion_.converted_cells())) > 0)
      conversion_.prepare(discretization_, particles_.body_names(), source_);
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

    for (auto *vec : {&d_, &v_, &v_now_, &f_, &f_ext_, &mass_, &d_phys_})
      discretization_.initialize_vector(*vec);
    // The FE lumped mass of every cell: particles at nodes keep it (formulation.md section 7).
    hex_.add_lumped_mass(mass_);
    mass_.compress(VectorOperation::add);
    mass_.update_ghost_values();
    contact_.prepare(discretization_, materials_, particles_, conversion_.converted_cells(), mass_, source_);
    {
      // The energy scale M c^2 of the model (total mass, fastest initial wave speed): a floor of
      // the energy error's reference, so that round-off in a model at rest is not reported as an
      // error of 1 (the reference is then round-off too).
      double wave_speed = 0;
      for (const auto &b : discretization_.bodies())
        if (const double c = materials_.get(b.material).initial_wave_speed(); std::isfinite(c))
          wave_speed = std::max(wave_speed, c);
      double mass = 0;
      for (unsigned int i = 0; i < mass_.locally_owned_size(); i += 3)
        mass += mass_.local_element(i);
      energy_floor_ = 1e-14 * Utilities::MPI::sum(mass, comm_) * wave_speed * wave_speed;
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
              v_.local_element(j + i) = value[i];
            if (non_finite.empty() && !(std::isfinite(value[0]) && std::isfinite(value[1]) && std::isfinite(value[2])))
              non_finite = discretization_.bodies()[k].name + "\n" + base::non_finite_at(*velocity, {x}, 0.);
          }
      }
    for (const auto &m : Utilities::MPI::all_gather(comm_, non_finite))
      if (!m.empty())
        {
          const auto name = m.substr(0, m.find('\n'));
          const auto body = discretization_.body_index(name);
          source_.fail("B - Mesh/" + name + "/initial velocity", discretization_.bodies()[body].initial_velocity,
                       "is not finite: " + m.substr(m.find('\n') + 1) + ".");
        }
    measure_partition();
    if (checkpoint_.restarting())
      restore_state();
    phase_time_[0] += std::chrono::duration<double>(Clock::now() - start).count();
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
    const auto         start = Clock::now();
    const unsigned int rank  = Utilities::MPI::this_mpi_process(comm_);
    RunResult          result{"completed", "", 0};
    phase_cpu_time.fill(0.);

    const bool restarted = step_ > 0;
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
    integrator_.rigid_bodies().prepare(discretization_, materials_, mass_);
    if (!restarted)
      {
        double ke = 0;
        for (unsigned int i = 0; i < v_.locally_owned_size(); ++i)
          ke += 0.5 * mass_.local_element(i) * v_.local_element(i) * v_.local_element(i);
        initial_energy_    = Utilities::MPI::sum(ke, comm_);
        initial_max_speed_ = fastest_node(v_).speed;
        balance_.boundary_work += conditions_.apply_initial(d_, mass_, v_);
        stable_dt_       = std::min(hex_.initial_stable_dt(), spg_.initial_stable_dt());
        first_stable_dt_ = Utilities::MPI::min(stable_dt_, comm_);
        if (!(first_stable_dt_ < 1e299) && !(integrator_.fixed_time_step() > 0))
          source_.fail("J - Time integration/fixed time step", "0",
                       "no element or particle limits the step (every body is rigid): set a fixed time step > 0. "
                       "Unit: s.");
        f_               = 0;
        f_ext_           = 0;
        conditions_.add_external_forces(0., f_ext_);
        f_ += f_ext_;
        dt_next_ = integrator_.next_dt(stable_dt_, 0.);
        integrator_.kick(0., 0., dt_next_, f_, f_ext_, mass_, d_, conditions_, v_, v_now_, balance_);
        d_.update_ghost_values();
        v_now_.update_ghost_values();
        try
          {
            record(); // the row waits in pending_rows_ until history.csv is opened below
          }
        catch (const fe::Instability &e)
          {
            return {"unstable", e.what(), 3, false};
          }
      }

    // From here the run owns its output directory.
    output_.create_directory();
    if (rank == 0)
      {
        if (restarted)
          {
            // Rows up to the checkpoint are kept (cut back in restore_state()); the run appends.
            history_.open(output_.directory() + "/history.csv", std::ios::app);
          }
        else
          {
            history_.open(output_.directory() + "/history.csv");
            history_ << "time,step,dt,kinetic_energy,internal_energy,hourglass_energy,external_work,boundary_work,"
                        "filter_work,conversion_energy,bond_energy,energy_error,momentum_x,momentum_y,momentum_z,"
                        "converted_elements,broken_bonds,free_particles,contact_energy,friction_energy,"
                        "contact_wall_force,contact_stored_energy,contact_lost_energy,contact_damping_energy";
            for (const auto &name : quantities_.names())
              history_ << "," << name;
            history_ << "\n" << pending_rows_;
            pending_rows_.clear();
          }
        std::ofstream used(output_.directory() + "/parameters.prm");
        prm_.print_parameters(used, ParameterHandler::ShortPRM | ParameterHandler::KeepDeclarationOrder);
        materials_.write_resolved_parameters(output_.directory() + "/generated_parameters.prm");
      }
    if (!restarted)
      {
        output_.write(0., physical_displacement(), v_now_);
        write_fragments();
        next_output_ = output_.interval();
      }

    auto         last_progress   = Clock::now();
    const auto   loop_start      = last_progress;
    const double loop_start_time = t_;
    base::ProgressEstimate pace; // ETA from the pace of the last progress lines
    const double end             = integrator_.end_time();
    // A restart from the checkpoint of the last step (or past a smaller end): no step is left,
    // and the run ends where the straight one did.
    bool stop = restarted && (t_ >= end * (1 - 1e-12) || (integrator_.max_steps() > 0 && step_ >= integrator_.max_steps()));
    if (stop && integrator_.max_steps() > 0 && step_ >= integrator_.max_steps() && t_ < end * (1 - 1e-12))
      result.status = "max steps reached";
    try
      {
        while (!stop)
          {
            // 1. Step size (computed from the candidates of the last force evaluation).
            {
              PhaseTimer timer(phase_time_, 1);
              dt_ = dt_next_;
            }
            // 2. Drift.
            {
              PhaseTimer timer(phase_time_, 2);
              integrator_.drift(dt_, v_, d_);
              t_ += dt_;
              ++step_;
            }
            // 3. Exchange: the only place where ghost values are set.
            {
              PhaseTimer timer(phase_time_, 3);
              d_.update_ghost_values();
              v_.update_ghost_values();
              contact_.exchange(d_, v_);
              // R1 filter steps smooth the particle coefficients and exchange once more.
              if (spg_.is_filter_step(step_))
                {
                  filter_work_ += spg_.filter(mass_, f_, d_, v_);
                  d_.update_ghost_values();
                  v_.update_ghost_values();
                }
            }
            // 5. FE internal force.
            std::string               failure;
            std::vector<unsigned int> to_convert;
            bool                      convert_now = false;
            {
              PhaseTimer timer(phase_time_, 5);
              f_ = 0;
              try
                {
                  element_steps_ += hex_.n_local_elements();
                  const auto r = hex_.add_internal_forces(d_, v_, dt_, step_, f_);
                  stable_dt_   = r.stable_dt;
                  internal_energy_ += r.internal_energy;
                  hourglass_energy_ += r.hourglass_energy;
                }
              catch (const fe::Instability &e)
                {
                  failure = e.what();
                }
            }
            // 6. Particle internal force.
            if (spg_.active())
              {
                PhaseTimer timer(phase_time_, 6);
                try
                  {
                    particle_steps_ += spg_.n_owned();
                    const auto r = spg_.add_internal_forces(d_, dt_, step_, f_);
                    stable_dt_   = std::min(stable_dt_, r.stable_dt);
                    particle_dt_ = r.stable_dt;
                    internal_energy_ += r.internal_energy;
                    stabilization_energy_ = r.stabilization_energy;
                  }
                catch (const fe::Instability &e)
                  {
                    failure += (failure.empty() ? "" : "; ") + std::string(e.what());
                  }
              }
            // 7. Loads.
            {
              PhaseTimer timer(phase_time_, 7);
              f_ext_ = 0;
              conditions_.add_external_forces(t_, f_ext_);
              // A contact spring acts in series with the element stiffness at its node, so its
              // limit combines with the force step: 1/dt^2 = 1/dt_force^2 + 1/dt_contact^2.
              if (contact_.active())
                {
                  const double dt_c = contact_.add_forces(step_, dt_, f_).stable_dt;
                  stable_dt_        = 1. / std::sqrt(1. / (stable_dt_ * stable_dt_) + 1. / (dt_c * dt_c));
                }
            }
            // 8. Accumulate: ghost force sums to their owners, one reduction of the step candidates.
            {
              PhaseTimer timer(phase_time_, 8);
              f_.compress(VectorOperation::add);
              f_ += f_ext_;
              // Elements that meet a conversion criterion at the end of this step.
              if (conversion_.is_check_step(step_) && failure.empty())
                to_convert = conversion_.candidates(hex_, d_);
              const double local[3] = {stable_dt_, failure.empty() ? 0. : -1., to_convert.empty() ? 0. : -1.};
              double       global[3];
              Utilities::MPI::min(ArrayView<const double>(local, 3), comm_, ArrayView<double>(global, 3));
              stable_dt_ = global[0];
              convert_now = global[2] < 0;
              if (global[1] < 0)
                {
                  std::string all;
                  for (const auto &m : Utilities::MPI::all_gather(comm_, failure))
                    if (!m.empty())
                      all += (all.empty() ? "" : "; ") + m;
                  // A load that became non-finite is the likely cause: name it.
                  throw fe::Instability(all + non_finite_source());
                }
            }
            // A collapsing step: stopped with the place of the smallest step (collective; every
            // rank has the same global step).
            // (Only rigid bodies at the start: the first finite step is the reference.)
            if (!(first_stable_dt_ < 1e299))
              first_stable_dt_ = stable_dt_;
            if (integrator_.minimum_step_fraction() > 0 &&
                stable_dt_ < integrator_.minimum_step_fraction() * first_stable_dt_)
              throw fe::Instability(collapsed_step_message());
            // 4b. Conversion (rare, collective): after the force of this step, before the
            // kick, so that stresses, history and d all belong to the end of the step.
            if (convert_now)
              {
                PhaseTimer timer(phase_time_, 4);
                convert(to_convert);
                to_convert.clear();
              }
            // 4c. Bond failure (collective on check steps), also after the force of this step:
            // the bonds are judged by this step's values; rows rebuilt, F reset to the new rows.
            if (bonds_.is_check_step(step_))
              {
                PhaseTimer timer(phase_time_, 4);
                const auto [broken, freed] = bonds_.update(discretization_, particles_, spg_, bond_values_);
                if (broken + freed > 0)
                  {
                    // The kick uses the forces of the new stencils (f_ext_ serves as work space
                    // for the change, then holds the loads again).
                    f_ext_ = 0;
                    const auto [a_rows, g_rows] = particles_.take_rebuilt_rows();
                    const double w              = spg_.refresh_forces(d_, f_ext_, a_rows, g_rows);
                    f_ext_.compress(VectorOperation::add);
                    f_ += f_ext_;
                    // The kick's kinetic energy (product form) sees the force change at once:
                    // dt/2 (f_new - f_old) . v^{n+1/2}, booked with the bond energy.
                    // (A local sum in the same order: the member would be reloaded at every term.)
                    double bond_energy = bond_energy_;
                    for (unsigned int i = 0; i < f_ext_.locally_owned_size(); ++i)
                      bond_energy += 0.5 * dt_ * f_ext_.local_element(i) * v_.local_element(i);
                    bond_energy_ = bond_energy;
                    f_ext_ = 0;
                    conditions_.add_external_forces(t_, f_ext_);
                    bond_energy_ += w - stabilization_energy_;
                    stabilization_energy_ = w;
                    fragments_stale_      = true; // prepared again at the next fragment output
                  }
              }
            const bool last = t_ >= end * (1 - 1e-12) ||
                              (integrator_.max_steps() > 0 && step_ >= integrator_.max_steps());
            // 9. Kick.
            {
              PhaseTimer timer(phase_time_, 9);
              dt_next_ = last ? dt_ : integrator_.next_dt(stable_dt_, t_);
              integrator_.kick(t_, dt_, dt_next_, f_, f_ext_, mass_, d_, conditions_, v_, v_now_, balance_);
            }
            // 10. Record: history, fields, progress (outside the step timer).
            {
              PhaseTimer timer(phase_time_, 10);
              if (step_ % output_.history_interval() == 0 || last)
                record();
              if (last || (output_.interval() > 0 && t_ >= next_output_ * (1 - 1e-12)))
                {
                  d_.update_ghost_values();
                  v_now_.update_ghost_values();
                  output_.write(t_, physical_displacement(), v_now_);
                  write_fragments();
                  while (next_output_ <= t_ * (1 + 1e-12) && output_.interval() > 0)
                    next_output_ += output_.interval();
                }
              const double since = std::chrono::duration<double>(Clock::now() - last_progress).count();
              if (rank == 0 && output_.progress_interval() > 0 && (since >= output_.progress_interval() || last))
                {
                  last_progress  = Clock::now();
                  pace.add(std::chrono::duration<double>(last_progress - loop_start).count(), t_);
                  const double eta = pace.remaining(end, loop_start_time);
                  std::fprintf(stderr,
                               "step %8u  t = %.4e s of %.4e s (%5.1f %%)  dt = %.3e s  energy error %+.2e  "
                               "ETA %.0f s\n",
                               step_, t_, end, 100. * t_ / end, dt_, energy_error_, eta);
                  history_.flush();
                }
              // Checkpoint: after the record, so that the tables it cuts back to hold this step.
              if (checkpoint_.is_due(step_))
                write_checkpoint();
              if (integrator_.max_steps() > 0 && step_ >= integrator_.max_steps() && t_ < end * (1 - 1e-12))
                result.status = "max steps reached";
              stop = last;
            }
          }
      }
    catch (const fe::Instability &e)
      {
        result = {"unstable", e.what(), 3};
      }
    history_.close();
    // Fragment statistics of the last output: by mass, largest first, with the cumulative
    // mass fraction, the speed, size, shape and the debris classification
    // (doc/manual/failure.md, "Fragments").
    if (rank == 0 && !last_fragments_.empty())
      {
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
                          f.equivalent_diameter, f.aspect_ratio, int(f.debris), int(f.dust), f.cone_angle,
                          f.origin[0], f.origin[1], f.origin[2]);
            out << row << discretization_.bodies()[f.body].name << shape;
          }
      }
    if (rank == 0 && !last_fragments_.empty() && output_.fragment_plots())
      {
        const std::string warning = base::run_plot_script(
          "plot_fragments.py", {output_.directory(), output_.directory() + "/fragments.png"});
        if (!warning.empty())
          std::cerr << "shard: warning: " << warning << "\n";
      }
    // Element-steps and particle-steps actually computed (conversion changes the counts).
    {
      const double local[2] = {element_steps_, particle_steps_};
      Utilities::MPI::sum(ArrayView<const double>(local, 2), comm_, ArrayView<double>(work_steps_.data(), 2));
    }
    write_summary(result, std::chrono::duration<double>(Clock::now() - start).count());

    if (rank == 0)
      {
        std::array<double, 11> max_time;
        Utilities::MPI::max(ArrayView<const double>(phase_time_.data(), 11), comm_,
                            ArrayView<double>(max_time.data(), 11));
        std::cerr << "\nTime per phase (largest over ranks; " << base::n_threads() << " thread(s) per rank):\n";
        double loop = 0;
        for (unsigned int p = 1; p < 11; ++p)
          loop += max_time[p];
        for (unsigned int p = 0; p < 11; ++p)
          if (max_time[p] > 0)
            std::fprintf(stderr, "  %-18s %10.3f s  %5.1f %%\n", phase_names[p], max_time[p],
                         p == 0 ? 0. : 100. * max_time[p] / loop);
        const double element_steps = work_steps_[0], particle_steps = work_steps_[1];
        if (max_time[5] > 0 && element_steps > 0)
          std::fprintf(stderr, "  FE force: %.3g element-steps/s (%.3f us per element-step)\n",
                       element_steps / max_time[5], 1e6 * max_time[5] / element_steps);
        if (max_time[6] > 0 && particle_steps > 0)
          std::fprintf(stderr, "  particle force: %.3g particle-steps/s (%.3f us per particle-step)\n",
                       particle_steps / max_time[6], 1e6 * max_time[6] / particle_steps);
      }
    else
      {
        Utilities::MPI::max(ArrayView<const double>(phase_time_.data(), 11), comm_,
                            ArrayView<double>(phase_time_.data(), 11));
      }
    return result;
  }

  void
  Simulation::record()
  {
    // One reduction of the energy terms and momentum.
    // The hourglass column holds the FE hourglass work plus the particle stabilization energy.
    // The internal energy includes the elastic energy changed by conversions; the conversion
    // energy (that change plus the jump of the stabilization energy) counts as a source.
    const double local[14] = {balance_.kinetic,       internal_energy_ + conversion_elastic_,
                              hourglass_energy_ + stabilization_energy_,
                              balance_.external_work, balance_.boundary_work, balance_.momentum[0],
                              balance_.momentum[1],   balance_.momentum[2],   filter_work_, bond_energy_,
                              contact_.energy(),      contact_.friction_energy(),
                              contact_.stored_energy(), contact_.damping_energy()};
    double       g[14];
    Utilities::MPI::sum(ArrayView<const double>(local, 14), comm_, ArrayView<double>(g, 14));
    // The contact energy (stored in the penalty springs plus dissipated by friction) counts
    // as internal energy.
    const double kinetic = g[0], internal = g[1] + g[2] + g[10], external = g[3], boundary = g[4], filter = g[8];
    const double bond = g[9];
    const double reference = std::max(initial_energy_ + std::abs(external) + std::abs(boundary) + std::abs(filter) +
                                        std::abs(conversion_energy_) + std::abs(bond),
                                      std::max(kinetic, energy_floor_));
    energy_error_ = reference > 0 ? (kinetic + internal - initial_energy_ - external - boundary - filter -
                                     conversion_energy_ - bond) /
                                      reference :
                                    0.;
    max_energy_error_ = std::max(max_energy_error_, std::abs(energy_error_));

    const auto q = quantities_.evaluate(physical_displacement(), v_now_, mass_, t_);
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

    if (Utilities::MPI::this_mpi_process(comm_) == 0)
      {
        std::string line;
        char        row[1024];
        std::snprintf(row, sizeof(row),
                      "%.16e,%u,%.16e,%.16e,%.16e,%.16e,%.16e,%.16e,%.16e,%.16e,%.16e,%.16e,%.16e,%.16e,%.16e,%llu,"
                      "%llu,%llu,%.16e,%.16e,%.16e,%.16e,%.16e,%.16e",
                      t_, step_, dt_next_, kinetic, internal, g[2], external, boundary, filter, conversion_energy_,
                      bond, energy_error_, g[5], g[6], g[7], conversion_.n_converted(), bonds_.n_broken(),
                      bonds_.n_free(), g[10], g[11], contact_.wall_force(), g[12], g[10] - g[11] - g[12] - g[13],
                      g[13]);
        line = row;
        for (const double x : q)
          {
            std::snprintf(row, sizeof(row), ",%.16e", x);
            line += row;
          }
        line += "\n";
        if (history_.is_open())
          history_ << line;
        else
          pending_rows_ += line;
      }
    const auto g6 = [](const double x) {
      std::ostringstream out;
      out << std::setprecision(6) << x;
      return out.str();
    };
    if (!std::isfinite(kinetic) || !std::isfinite(internal))
      throw fe::Instability("step " + std::to_string(step_) + ", t = " + g6(t_) + " s: non-finite energy (kinetic " +
                            g6(kinetic) + " J, internal " + g6(internal) + " J)" + non_finite_source());
    // Every other column of the row: a run never ends with a non-finite value in its history.
    {
      const std::vector<std::pair<std::string, double>> terms = {
        {"external_work", external}, {"boundary_work", boundary}, {"filter_work", filter},
        {"conversion_energy", conversion_energy_}, {"bond_energy", bond}, {"energy_error", energy_error_},
        {"momentum_x", g[5]}, {"momentum_y", g[6]}, {"momentum_z", g[7]}, {"contact_energy", g[10]},
        {"friction_energy", g[11]}, {"contact_stored_energy", g[12]}, {"contact_damping_energy", g[13]},
        {"dt", dt_next_}};
      for (const auto &[name, value] : terms)
        if (!std::isfinite(value))
          throw fe::Instability("step " + std::to_string(step_) + ", t = " + g6(t_) + " s: " + name + " is " +
                                g6(value) + non_finite_source());
      for (unsigned int i = 0; i < q.size(); ++i)
        if (!std::isfinite(q[i]))
          throw fe::Instability("step " + std::to_string(step_) + ", t = " + g6(t_) + " s: quantity '" +
                                quantities_.names()[i] + "' (L - Quantities/quantities) is " + g6(q[i]));
    }
    if (std::abs(energy_error_) > integrator_.energy_error_limit())
      throw fe::Instability("step " + std::to_string(step_) + ", t = " + g6(t_) + " s: energy error " +
                            g6(energy_error_) + " exceeds the limit " + g6(integrator_.energy_error_limit()) +
                            " (kinetic " + g6(kinetic) + " J, internal " + g6(internal) + " J, external work " +
                            g6(external) + " J, boundary work " + g6(boundary) + " J, initial kinetic " +
                            g6(initial_energy_) + " J); " + fastest_node(v_now_).describe());
  }

  std::string
  Simulation::non_finite_source() const
  {
    for (const auto &m : Utilities::MPI::all_gather(comm_, conditions_.non_finite_report(t_)))
      if (!m.empty())
        return "; " + m;
    return "";
  }

  std::string
  Simulation::collapsed_step_message() const
  {
    // The element or particle of this rank with the smallest own step, then of all ranks; ties
    // go to elements before particles, then to the smaller cell index or global particle id, so
    // the answer does not depend on the partition.
    double             best = 1e300;
    unsigned long long kind = 2, id = 0;
    std::string        place;
    for (unsigned int e = 0; e < hex_.n_local_elements(); ++e)
      if (hex_.element_stable_dt(e) < best || (hex_.element_stable_dt(e) == best && hex_.cell_index(e) < id))
        {
          best  = hex_.element_stable_dt(e);
          kind  = 0;
          id    = hex_.cell_index(e);
          place = hex_.describe(e, d_);
        }
    if (spg_.active() && spg_.n_owned() > 0 && particle_dt_ < best)
      {
        const unsigned int i = spg_.smallest_step_particle();
        best                 = particle_dt_;
        kind                 = 1;
        id                   = particles_.global_id(i);
        place                = spg_.describe(i);
      }
    std::ostringstream local;
    local << std::setprecision(17) << best << " " << kind << " " << id << " " << place;
    double             smallest = 1e300;
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
    out << std::setprecision(6) << "step " << step_ << ", t = " << t_ << " s: the stable step " << stable_dt_
        << " s fell below " << integrator_.minimum_step_fraction() << " of the first step " << first_stable_dt_
        << " s (J - Time integration/minimum step fraction); smallest step " << smallest << " s in " << where;
    return out.str();
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
                     X.local_element(i) + d_.local_element(i), X.local_element(i + 1) + d_.local_element(i + 1),
                     X.local_element(i + 2) + d_.local_element(i + 2)}};
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

  namespace
  {
    /**
     * Stored elastic energy density estimate (J per reference m^3): K (ln J)^2 / 2 from the
     * relative volume (the pressure of the elastic and von Mises models is K ln J) plus
     * s : s / (4 G) from the stored deviatoric stress; K, G of the undamaged material.
     */
    double
    elastic_energy_density(const materials::Material &m, const double *s, const double jacobian)
    {
      const auto   kg = m.elastic_moduli();
      const double p  = (s[0] + s[1] + s[2]) / 3.;
      double       ss = 0;
      for (unsigned int c = 0; c < 3; ++c)
        ss += (s[c] - p) * (s[c] - p) + 2 * s[c + 3] * s[c + 3];
      const double lj = std::log(jacobian);
      return 0.5 * kg[0] * lj * lj + ss / (4 * kg[1]);
    }

    /// Moves the owned values of @p v to the layout of @p partitioner (ghosts zero).
    void
    move_to_layout(mesh::Vector &v, const std::shared_ptr<const Utilities::MPI::Partitioner> &partitioner)
    {
      if (v.get_partitioner() == partitioner)
        return;
      std::vector<double> owned(v.begin(), v.end());
      v.reinit(partitioner);
      std::copy(owned.begin(), owned.end(), v.begin());
    }
  } // namespace

  void
  Simulation::convert(const std::vector<unsigned int> &elements)
  {
    std::vector<unsigned int> cells;
    for (const unsigned int e : elements)
      cells.push_back(hex_.cell_index(e));
    const unsigned long long added = conversion_.add_cells(cells);
    if (added == 0)
      return;

    // Volume-weighted history of the converted elements at their nodes: weight V_e / 8, then
    // the six stresses and the history slots, packed three per node into distributed vectors.
    unsigned int max_slots = 0;
    for (const unsigned int e : elements)
      max_slots = std::max(max_slots, hex_.material(e).n_state_slots());
    max_slots                    = Utilities::MPI::max(max_slots, comm_);
    const unsigned int n_values  = 7 + max_slots;
    std::vector<mesh::Vector> acc((n_values + 2) / 3);
    for (auto &a : acc)
      discretization_.initialize_vector(a);
    double energy[2] = {0, 0}; // elastic energy before and after, this rank
    for (const unsigned int e : elements)
      {
        const auto  &m = hex_.material(e);
        const double w = hex_.reference_volume(e) / 8;
        std::vector<double> values(n_values, 0.);
        values[0] = 1;
        std::copy(hex_.stress(e), hex_.stress(e) + 6, &values[1]);
        std::copy(hex_.state(e), hex_.state(e) + m.n_state_slots(), &values[7]);
        for (unsigned int a = 0; a < 8; ++a)
          for (unsigned int k = 0; k < n_values; ++k)
            acc[k / 3].local_element(hex_.node(e, a) + k % 3) += w * values[k];
        double x[8][3], B[8][3];
        for (unsigned int a = 0; a < 8; ++a)
          for (unsigned int c = 0; c < 3; ++c)
            {
              const unsigned int j = hex_.node(e, a) + c;
              x[a][c]              = discretization_.reference_positions().local_element(j) + d_.local_element(j);
            }
        const double jacobian = fe::hex_volume_gradient(x, B) / hex_.reference_volume(e);
        energy[0] += elastic_energy_density(m, hex_.stress(e), jacobian) * hex_.reference_volume(e);
      }
    for (auto &a : acc)
      a.compress(VectorOperation::add);
    const auto saved = spg_.save_state();
    const double old_stabilization = Utilities::MPI::sum(stabilization_energy_, comm_);

    // New particle set, stencils and ghost set; vectors and element nodes follow the layout.
    hex_.remove_elements(elements);
    const auto old_partitioner = discretization_.partitioner();
    particles_.prepare(discretization_, conversion_.converted_cells(), conditions_.faces(), source_);
    const auto &partitioner = discretization_.partitioner();
    if (partitioner != old_partitioner)
      {
        hex_.relocalize(*old_partitioner, *partitioner);
        for (auto *vec : {&d_, &v_, &v_now_, &f_, &f_ext_, &mass_, &d_phys_})
          move_to_layout(*vec, partitioner);
        for (auto &a : acc)
          move_to_layout(a, partitioner);
      }
    spg_.prepare(discretization_, particles_, materials_);
    bonds_.prepare(particles_, spg_, source_);

    // History of every owned particle: kept, or the volume average of what it had and what
    // its newly converted cells bring, h = (V_old h_old + sum V_e/8 h_e) / V_new.
    std::vector<double>       mixed(n_values);
    std::vector<unsigned int> received;
    for (unsigned int i = 0; i < spg_.n_owned(); ++i)
      {
        const unsigned int j  = particles_.local_dof(i);
        const auto         it = saved.find(particles_.global_id(i));
        const auto        &m  = spg_.material(i);
        const double       w  = acc[0].local_element(j);
        if (w == 0)
          {
            if (it != saved.end())
              spg_.set_state(i, it->second.stress.data(), it->second.state.data(), it->second.q);
            continue;
          }
        const double v_old = it != saved.end() ? it->second.volume : 0.;
        const double v_new = v_old + w;
        if (std::abs(v_new - particles_.volume(i)) > 1e-9 * v_new)
          throw std::logic_error("conversion: particle volume " + std::to_string(particles_.volume(i)) +
                                 " differs from the transferred " + std::to_string(v_new));
        for (unsigned int k = 1; k < n_values; ++k)
          mixed[k] = acc[k / 3].local_element(j + k % 3);
        if (it != saved.end())
          {
            for (unsigned int c = 0; c < 6; ++c)
              mixed[1 + c] += v_old * it->second.stress[c];
            for (unsigned int k = 0; k < it->second.state.size(); ++k)
              mixed[7 + k] += v_old * it->second.state[k];
            energy[0] += elastic_energy_density(m, it->second.stress.data(), it->second.jacobian) * v_old;
          }
        for (unsigned int k = 1; k < n_values; ++k)
          mixed[k] /= v_new;
        spg_.set_state(i, &mixed[1], &mixed[7], it != saved.end() ? it->second.q : 0.);
        received.push_back(i);
      }

    // Kinematics of the new stencils from the current coefficients, then the energy after.
    d_.update_ghost_values();
    v_.update_ghost_values();
    spg_.keep_residuals(d_, saved);
    stabilization_energy_ = spg_.reset_deformation(d_);
    // The particles that existed keep their relative volume J = c det F across the new
    // stencils (SpgForce::volume_factor); new particles start at c = 1.
    for (unsigned int i = 0; i < spg_.n_owned(); ++i)
      {
        const auto   it = saved.find(particles_.global_id(i));
        const double j  = spg_.jacobian(i);
        if (it != saved.end() && j > 0)
          spg_.set_volume_factor(i, it->second.jacobian / j);
      }
    for (const unsigned int i : received)
      energy[1] += elastic_energy_density(spg_.material(i), spg_.stress(i), spg_.jacobian(i)) * particles_.volume(i);

    physical_step_ = ~0u;
    quantities_.prepare(discretization_, hex_, conditions_, spg_, source_);
    fragments_.prepare(discretization_, hex_, particles_);
    contact_.prepare(discretization_, materials_, particles_, conversion_.converted_cells(), mass_, source_);
    stable_dt_ = std::min(stable_dt_, spg_.current_stable_dt());

    Utilities::MPI::sum(ArrayView<const double>(energy, 2), comm_, ArrayView<double>(energy, 2));
    const double elastic = energy[1] - energy[0];
    const double change  = elastic + Utilities::MPI::sum(stabilization_energy_, comm_) - old_stabilization;
    conversion_elastic_ += Utilities::MPI::this_mpi_process(comm_) == 0 ? elastic : 0.;
    conversion_energy_ += change;
    if (Utilities::MPI::this_mpi_process(comm_) == 0)
      std::fprintf(stderr,
                   "step %8u  conversion: %llu cells (%llu converted in all), %llu particles; energy change "
                   "%.3e J (elastic %.3e J), %.3e J in all\n",
                   step_, added, conversion_.n_converted(), particles_.n_global(), change, elastic,
                   conversion_energy_);
  }

  const mesh::Vector &
  Simulation::physical_displacement()
  {
    if (!spg_.active() || physical_step_ == step_)
      return spg_.active() ? d_phys_ : d_;
    physical_step_ = step_;
    d_phys_        = d_;
    spg_.physical_displacement(d_phys_);
    d_phys_.update_ghost_values();
    return d_phys_;
  }

  void
  Simulation::write_fragments()
  {
    if (!particles_.active())
      return;
    if (fragments_stale_)
      fragments_.prepare(discretization_, hex_, particles_);
    fragments_stale_     = false;
    last_fragments_      = fragments_.compute(physical_displacement(), v_now_, mass_);
    last_fragments_time_ = t_;
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
        std::snprintf(row, sizeof(row), "%.10e,%llu,%llu,%llu,%.16e,%.10e,%.10e,%.10e,%.10e,%.10e,%.10e,%.10e\n", t_,
                      f.id, f.nodes, f.particles, f.mass, f.centre[0], f.centre[1], f.centre[2], f.velocity[0],
                      f.velocity[1], f.velocity[2], f.kinetic_energy);
        out << row;
      }
  }

  void
  Simulation::write_summary(const RunResult &result, const double wall_time) const
  {
    std::array<double, 11> max_time;
    Utilities::MPI::max(ArrayView<const double>(phase_time_.data(), 11), comm_,
                        ArrayView<double>(max_time.data(), 11));
    // Memory: solver-owned particle data and the distributed vectors of the time loop (summed
    // over ranks), peak resident set size (largest over ranks; ru_maxrss is in KiB on Linux).
    double memory[2] = {particles_.active() ? double(particles_.memory_consumption() + spg_.memory_consumption()) : 0.,
                        0.};
    for (const auto *vec : {&d_, &v_, &v_now_, &f_, &f_ext_, &mass_, &d_phys_})
      memory[1] += vec->memory_consumption();
    Utilities::MPI::sum(ArrayView<const double>(memory, 2), comm_, ArrayView<double>(memory, 2));
    const double element_bytes = Utilities::MPI::sum(double(hex_.memory_consumption()), comm_);
    const double n_hexes       = Utilities::MPI::sum(double(hex_.n_local_elements()), comm_);
    const auto   rank_times    = Utilities::MPI::all_gather(comm_, std::vector<double>(phase_time_.begin(), phase_time_.end()));
    const auto   rank_cpu      = Utilities::MPI::all_gather(comm_, std::vector<double>(phase_cpu_time.begin(), phase_cpu_time.end()));
    rusage usage{};
    getrusage(RUSAGE_SELF, &usage);
    const double peak_rss = Utilities::MPI::max(1024. * usage.ru_maxrss, comm_);
    if (Utilities::MPI::this_mpi_process(comm_) != 0)
      return;
    std::ostringstream j;
    j << "{\n";
    j << "  \"shard_version\": \"" << version_string << " (" << git_description << ")\",\n";
    j << "  \"title\": \"" << base::json_escape(title_) << "\",\n";
    j << "  \"parameter_file\": \"" << base::json_escape(source_.filename()) << "\",\n";
    j << "  \"status\": \"" << result.status << "\",\n";
    if (!result.message.empty())
      j << "  \"message\": \"" << base::json_escape(result.message) << "\",\n";
    j << "  \"steps\": " << step_ << ",\n";
    j << "  \"final_time\": " << number(t_) << ",\n";
    j << "  \"last_dt\": " << number(dt_) << ",\n";
    j << "  \"wall_time_s\": " << number(wall_time + max_time[0]) << ",\n";
    j << "  \"n_elements\": " << discretization_.n_elements() << ",\n";
    j << "  \"n_particles\": " << particles_.n_global() << ",\n";
    j << "  \"n_converted_elements\": " << conversion_.n_converted() << ",\n";
    j << "  \"conversion_events\": " << conversion_.n_events() << ",\n";
    j << "  \"conversion_energy\": " << number(conversion_energy_) << ",\n";
    j << "  \"broken_bonds\": " << bonds_.n_broken() << ",\n";
    j << "  \"free_particles\": " << bonds_.n_free() << ",\n";
    j << "  \"contact_rebuilds\": " << contact_.n_rebuilds() << ",\n";
    if (!last_fragments_.empty())
      {
        double total = 0, largest = 0;
        for (const auto &f : last_fragments_)
          total += f.mass, largest = std::max(largest, f.mass);
        j << "  \"n_fragments\": " << last_fragments_.size() << ",\n";
        j << "  \"fragment_mass_total\": " << number(total) << ",\n";
        j << "  \"largest_fragment_mass\": " << number(largest) << ",\n";
        // Debris and dust (doc/manual/failure.md, "Fragments").
        // (17 digits: the masses add up to the total to round-off.)
        const auto s      = output::summarize(last_fragments_);
        const auto axis   = output_.debris_axis();
        const auto number = [](const double x) {
          std::ostringstream o;
          o << std::setprecision(17) << x;
          return std::isfinite(x) ? o.str() : std::string("null");
        };
        j << "  \"fragments\": {\"time\": " << number(last_fragments_time_) << ", \"count\": " << s.count
          << ", \"mass\": " << number(s.mass) << ", \"dust_particles\": " << output_.dust_particles()
          << ", \"debris_axis\": [" << number(axis[0]) << ", " << number(axis[1]) << ", " << number(axis[2])
          << "], \"body_mass\": " << number(s.body_mass) << ", \"debris_count\": " << s.debris_count
          << ", \"debris_mass\": " << number(s.debris_mass) << ", \"dust_count\": " << s.dust_count
          << ", \"dust_mass\": " << number(s.dust_mass) << ", \"dust_fraction\": " << number(s.dust_fraction)
          << ", \"coarse_debris_mass\": " << number(s.coarse_debris_mass)
          << ", \"coarse_debris_fraction\": " << number(s.coarse_debris_fraction)
          << ", \"largest_debris_mass\": " << number(s.largest_debris_mass)
          << ", \"fastest_debris_speed\": " << number(s.fastest_debris_speed)
          << ", \"median_coarse_debris_mass\": " << number(s.median_coarse_debris_mass)
          << ", \"debris_cone_angle_mean\": " << number(s.cone_angle_mean)
          << ", \"debris_cone_angle_90\": " << number(s.cone_angle_90) << "},\n";
      }
    j << "  \"correction_iterations\": " << spg_.correction_solve().iterations << ",\n";
    j << "  \"n_mpi_ranks\": " << Utilities::MPI::n_mpi_processes(comm_) << ",\n";
    j << "  \"n_threads\": " << base::n_threads() << ",\n";
    j << "  \"energy_error\": " << number(energy_error_) << ",\n";
    j << "  \"max_abs_energy_error\": " << number(max_energy_error_) << ",\n";
    const double element_steps = work_steps_[0], particle_steps = work_steps_[1];
    j << "  \"element_steps_per_s\": " << number(max_time[5] > 0 ? element_steps / max_time[5] : 0) << ",\n";
    j << "  \"us_per_element_step\": " << number(element_steps > 0 ? 1e6 * max_time[5] / element_steps : 0)
      << ",\n";
    const double n_particles = particles_.n_global();
    j << "  \"particle_steps_per_s\": " << number(max_time[6] > 0 ? particle_steps / max_time[6] : 0) << ",\n";
    j << "  \"us_per_particle_step\": " << number(particle_steps > 0 ? 1e6 * max_time[6] / particle_steps : 0)
      << ",\n";
    j << "  \"particle_bytes\": " << number(memory[0]) << ",\n";
    j << "  \"bytes_per_particle\": " << number(n_particles > 0 ? memory[0] / n_particles : 0) << ",\n";
    j << "  \"n_dofs\": " << d_.size() << ",\n";
    j << "  \"vector_bytes\": " << number(memory[1]) << ",\n";
    j << "  \"vector_bytes_per_dof\": " << number(d_.size() > 0 ? memory[1] / d_.size() : 0) << ",\n";
    j << "  \"element_bytes\": " << number(element_bytes) << ",\n";
    j << "  \"bytes_per_element\": " << number(n_hexes > 0 ? element_bytes / n_hexes : 0) << ",\n";
    j << "  \"peak_rss_bytes\": " << number(peak_rss) << ",\n";
    const auto list = [&](const std::vector<double> &x) {
      std::string out;
      for (unsigned int r = 0; r < x.size(); ++r)
        out += (r ? ", " : "") + number(x[r]);
      return "[" + out + "]";
    };
    j << "  \"partition\": {\"particle_weight\": " << number(discretization_.particle_weight())
      << ", \"elements_per_rank\": " << list(rank_elements_) << ", \"particles_per_rank\": " << list(rank_particles_)
      << ", \"work_imbalance\": " << number(imbalance_) << ", \"work_imbalance_cell_count\": "
      << number(imbalance_before_) << "},\n";
    j << "  \"phase_time_by_rank_s\": [";
    for (unsigned int r = 0; r < rank_times.size(); ++r)
      j << (r ? ", " : "") << list(rank_times[r]);
    j << "],\n";
    j << "  \"phase_cpu_time_by_rank_s\": [";
    for (unsigned int r = 0; r < rank_cpu.size(); ++r)
      j << (r ? ", " : "") << list(rank_cpu[r]);
    j << "],\n";
    j << "  \"phase_time_s\": {";
    for (unsigned int p = 0; p < 11; ++p)
      j << (p ? ", " : "") << "\"" << phase_names[p] << "\": " << number(max_time[p]);
    j << "},\n";
    j << "  \"results\": {";
    const auto names = quantities_.names();
    for (unsigned int i = 0; i < names.size(); ++i)
      j << (i ? ", " : "") << "\"" << base::json_escape(names[i]) << "\": " << number(q_final_[i]) << ", \""
        << base::json_escape(names[i]) << "_min\": " << number(q_min_[i]) << ", \"" << base::json_escape(names[i])
        << "_max\": " << number(q_max_[i]);
    j << "},\n";
    j << "  \"files\": {\"history\": \"" << base::json_escape(output_.directory()) << "/history.csv\", \"fields\": \""
      << base::json_escape(output_.pvd_path()) << "\", \"parameters\": \"" << base::json_escape(output_.directory())
      << "/parameters.prm\"}\n";
    j << "}\n";
    base::write_file_atomically(output_.directory() + "/summary.json", j.str());
  }

  namespace
  {
    using Bond = particles::ParticleSet::Bond;
    using Keys = std::vector<unsigned long long>;

    /// The part of a checkpoint that is the same on every rank (read from rank 0's file).
    struct SavedGlobal
    {
      unsigned int                                               step = 0;
      double                                                     t = 0, dt = 0, dt_next = 0, stable_dt = 0;
      double                                                     conversion_energy = 0, reference_energy = 0;
      double                                                     initial_energy = 0, energy_error = 0;
      double                                                     max_energy_error = 0, first_stable_dt = 0;
      double                                                     initial_max_speed = 0, next_output = 0;
      double                                                     held_dt = 0, last_fragments_time = -1;
      std::vector<double>                                        q_final, q_min, q_max;
      std::array<std::vector<std::pair<double, std::string>>, 2> records;
      unsigned char                                              fragments_started = 0;
      unsigned long long                                         history_bytes = 0, fragments_bytes = 0;
      std::uint64_t                                              history_hash = 0, fragments_hash = 0;
      std::vector<unsigned int>                                  converted;
      unsigned int                                               n_events = 0, n_rebuilds = 0;
      std::vector<std::pair<unsigned long long, unsigned long long>> bonds_at_prepare, bonds;
      Keys                                                       free_at_prepare, free;
      unsigned long long                                         n_broken = 0, n_free = 0;
    };

    /// One rank's share: its scalars and its owned nodes, elements and particles.
    struct SavedRank
    {
      Keys                      ghosts;
      std::vector<double>       scalars;
      double                    contact_energy = 0, friction_energy = 0;
      Keys                      node_keys;
      std::vector<double>       node_values; // d, v, v_now, f, f_ext: 15 per node
      std::vector<unsigned int> cells;
      Keys                      element_offsets, particle_keys, particle_offsets;
      std::vector<double>       element_values, particle_values;
      unsigned char             has_contact = 0;
      std::vector<unsigned int> changed_rows; // ParticleSet::changed_rows(), local rows
    };

    /// One list of fields for writing and reading (@p io is put or get).
    template <typename IO>
    void
    serialize(IO &&io, SavedGlobal &g)
    {
      io(g.step), io(g.t), io(g.dt), io(g.dt_next), io(g.stable_dt), io(g.conversion_energy);
      io(g.reference_energy), io(g.initial_energy), io(g.energy_error), io(g.max_energy_error);
      io(g.first_stable_dt), io(g.initial_max_speed), io(g.next_output), io(g.held_dt);
      io(g.last_fragments_time), io(g.q_final), io(g.q_min), io(g.q_max), io(g.records);
      io(g.fragments_started), io(g.history_bytes), io(g.fragments_bytes), io(g.history_hash);
      io(g.fragments_hash), io(g.converted), io(g.n_events);
      io(g.n_rebuilds), io(g.bonds_at_prepare), io(g.bonds), io(g.free_at_prepare), io(g.free);
      io(g.n_broken), io(g.n_free);
    }

    template <typename IO>
    void
    serialize(IO &&io, SavedRank &r)
    {
      io(r.ghosts), io(r.scalars), io(r.contact_energy), io(r.friction_energy), io(r.node_keys);
      io(r.node_values), io(r.cells), io(r.element_offsets), io(r.element_values), io(r.particle_keys);
      io(r.particle_offsets), io(r.particle_values), io(r.has_contact), io(r.changed_rows);
    }

    /// Reads header, global and rank part of one payload; @p reader stays after them.
    void
    read_payload(base::BinaryReader &reader, SavedGlobal &g, SavedRank &r)
    {
      reader.expect("shard state");
      reader.get<unsigned int>();
      reader.get<unsigned int>();
      reader.expect("global");
      serialize([&](auto &x) { reader.get(x); }, g);
      reader.expect("rank");
      serialize([&](auto &x) { reader.get(x); }, r);
    }
  } // namespace

  std::string
  Simulation::fingerprint() const
  {
    // The parameters as read, without the keys a restart may change.
    std::ostringstream all;
    prm_.print_parameters(all, ParameterHandler::ShortPRM | ParameterHandler::KeepDeclarationOrder);
    std::istringstream in(all.str());
    std::ostringstream out;
    std::string        line, top;
    int                depth = 0;
    while (std::getline(in, line))
      {
        const auto first = line.find_first_not_of(' ');
        if (first == std::string::npos)
          continue;
        const std::string l = line.substr(first);
        if (l.rfind("subsection ", 0) == 0)
          {
            if (depth++ == 0)
              top = l.substr(11);
            continue;
          }
        if (l == "end")
          {
            --depth;
            continue;
          }
        if (top == "K - Output" || top == "N - Checkpoint" || l.rfind("set end time", 0) == 0 ||
            l.rfind("set max steps", 0) == 0 || l.rfind("set title", 0) == 0)
          continue;
        out << top << ": " << l << "\n";
      }
    out << "dofs " << discretization_.dof_handler().n_dofs() << " cells " << discretization_.n_elements() << "\n";
    return out.str();
  }

  void
  Simulation::write_checkpoint()
  {
    const unsigned int rank = Utilities::MPI::this_mpi_process(comm_);
    const auto        &pt   = *discretization_.partitioner();
    const auto key_bonds = [&](const std::vector<Bond> &bonds) {
      std::vector<std::pair<unsigned long long, unsigned long long>> out;
      for (const auto &[a, b] : bonds)
        out.emplace_back(checkpoint_.key_of_node(a), checkpoint_.key_of_node(b));
      return out;
    };
    const auto key_nodes = [&](const Keys &ids) {
      Keys out;
      for (const auto id : ids)
        out.push_back(checkpoint_.key_of_node(id));
      return out;
    };

    SavedGlobal g;
    g.step = step_, g.t = t_, g.dt = dt_, g.dt_next = dt_next_, g.stable_dt = stable_dt_;
    g.conversion_energy = conversion_energy_, g.reference_energy = reference_energy_;
    g.initial_energy = initial_energy_, g.energy_error = energy_error_, g.max_energy_error = max_energy_error_;
    g.first_stable_dt = first_stable_dt_, g.initial_max_speed = initial_max_speed_, g.next_output = next_output_;
    g.held_dt = integrator_.held_dt(), g.last_fragments_time = last_fragments_time_;
    g.q_final = q_final_, g.q_min = q_min_, g.q_max = q_max_, g.records = output_.records();
    g.fragments_started = fragments_started_;
    if (rank == 0)
      {
        history_.flush();
        const std::string fragments = output_.directory() + "/fragments.csv";
        g.history_bytes             = std::filesystem::file_size(output_.directory() + "/history.csv");
        g.fragments_bytes = std::filesystem::exists(fragments) ? std::filesystem::file_size(fragments) : 0;
        // The content, so that a restart continues these very tables (not only as long ones).
        g.history_hash   = base::fnv1a(file_head(output_.directory() + "/history.csv", g.history_bytes));
        g.fragments_hash = base::fnv1a(file_head(fragments, g.fragments_bytes));
      }
    // Each rank knows the converted cells it holds; its owned ones are written (the union over
    // the ranks is the converted set).
    for (const auto &cell : discretization_.triangulation().active_cell_iterators())
      if (cell->is_locally_owned() && conversion_.converted_cells()[cell->active_cell_index()])
        g.converted.push_back(cell->active_cell_index());
    g.n_events = conversion_.n_events(), g.n_rebuilds = contact_.n_rebuilds();
    if (particles_.active())
      {
        g.bonds_at_prepare = key_bonds(particles_.bonds_at_prepare());
        g.bonds            = key_bonds(particles_.broken_bonds());
        g.free_at_prepare  = key_nodes(particles_.free_at_prepare());
        g.free             = key_nodes(particles_.free_particles());
      }
    g.n_broken = bonds_.n_broken(), g.n_free = bonds_.n_free();

    SavedRank r;
    for (const auto i : pt.ghost_indices())
      r.ghosts.push_back(i);
    r.scalars = {internal_energy_,
                 hourglass_energy_,
                 stabilization_energy_,
                 filter_work_,
                 conversion_elastic_,
                 bond_energy_,
                 balance_.kinetic,
                 balance_.momentum[0],
                 balance_.momentum[1],
                 balance_.momentum[2],
                 balance_.external_work,
                 balance_.boundary_work,
                 balance_.pending_external,
                 balance_.pending_boundary,
                 element_steps_,
                 particle_steps_,
                 particle_dt_};
    r.contact_energy = contact_.energy(), r.friction_energy = contact_.friction_energy();
    for (unsigned int j = 0; j < pt.locally_owned_size(); j += 3)
      {
        r.node_keys.push_back(checkpoint_.key_of_local_dof(j));
        for (const auto *vec : {&d_, &v_, &v_now_, &f_, &f_ext_})
          for (unsigned int c = 0; c < 3; ++c)
            r.node_values.push_back(vec->local_element(j + c));
      }
    r.element_offsets.push_back(0);
    for (unsigned int e = 0; e < hex_.n_local_elements(); ++e)
      {
        r.cells.push_back(hex_.cell_index(e));
        const auto values = hex_.checkpoint_values(e);
        r.element_values.insert(r.element_values.end(), values.begin(), values.end());
        r.element_offsets.push_back(r.element_values.size());
      }
    r.particle_offsets.push_back(0);
    if (spg_.active())
      for (const auto &[id, p] : spg_.save_state())
        {
          r.particle_keys.push_back(checkpoint_.key_of_node(id));
          r.particle_values.insert(r.particle_values.end(), p.stress.begin(), p.stress.end());
          r.particle_values.push_back(p.q);
          r.particle_values.insert(r.particle_values.end(), p.state.begin(), p.state.end());
          r.particle_values.push_back(p.volume_factor);
          r.particle_values.insert(r.particle_values.end(), p.residual_offset.begin(), p.residual_offset.end());
          r.particle_offsets.push_back(r.particle_values.size());
        }
    r.has_contact = contact_.active();
    if (particles_.active())
      r.changed_rows = particles_.changed_rows();

    base::BinaryWriter w;
    w.put(std::string("shard state"));
    w.put(Utilities::MPI::n_mpi_processes(comm_));
    w.put(rank);
    w.put(std::string("global"));
    serialize([&](auto &x) { w.put(x); }, g);
    w.put(std::string("rank"));
    serialize([&](auto &x) { w.put(x); }, r);
    if (r.has_contact)
      {
        // Exact at the same partition; portable (by node key) for another rank count.
        base::BinaryWriter exact;
        contact_.save(exact);
        w.put(exact.str());
        auto portable = contact_.portable_state([&](const unsigned long long n) { return checkpoint_.key_of_node(n); });
        portable.serialize([&](auto &x) { w.put(x); });
      }
    w.put(std::string("end"));
    checkpoint_.write(step_, t_, w.str());
  }

  void
  Simulation::restore_topology()
  {
    const std::string         key = "N - Checkpoint/restart from";
    SavedGlobal               g;
    SavedRank                 r;
    std::vector<unsigned int> converted;
    try
      {
        const unsigned int own = checkpoint_.same_rank_count() ? Utilities::MPI::this_mpi_process(comm_) : 0;
        for (unsigned int q = 0; q < checkpoint_.restart_ranks(); ++q)
          {
            base::BinaryReader reader(checkpoint_.payload(q));
            SavedGlobal        gq;
            SavedRank          rq;
            read_payload(reader, gq, rq);
            converted.insert(converted.end(), gq.converted.begin(), gq.converted.end());
            if (q == 0)
              g = std::move(gq);
            if (q == own)
              r = std::move(rq);
          }
        std::sort(converted.begin(), converted.end());
        converted.erase(std::unique(converted.begin(), converted.end()), converted.end());
      }
    catch (const std::exception &e)
      {
        source_.fail(key, checkpoint_.restart_manifest(), std::string("cannot read the checkpoint: ") + e.what());
      }
    const auto node_bonds = [&](const std::vector<std::pair<unsigned long long, unsigned long long>> &keys) {
      std::vector<Bond> out;
      for (const auto &[a, b] : keys)
        out.emplace_back(checkpoint_.node_of_key(a), checkpoint_.node_of_key(b));
      for (auto &b : out)
        if (b.first > b.second)
          std::swap(b.first, b.second);
      return out;
    };
    const auto nodes = [&](const Keys &keys) {
      Keys out;
      for (const auto k : keys)
        out.push_back(checkpoint_.node_of_key(k));
      return out;
    };
    for (const auto c : converted)
      if (c >= conversion_.converted_cells().size())
        source_.fail(key, checkpoint_.restart_manifest(), "the checkpoint names a cell this mesh does not have.");
    conversion_.restore(converted, g.n_events);
    particles_.restore_broken(node_bonds(g.bonds_at_prepare), nodes(g.free_at_prepare));
    // Rows rebuilt for broken bonds use the failure condition limit, which the run had set
    // (BondFailure::prepare) before every rebuild of the particle set after the first.
    particles_.set_broken_condition_limit(bonds_.condition_limit());
    // The same ghost set as the run that wrote the checkpoint (it only grows at conversions),
    // so that local indices and the order of every sum are the same.
    if (checkpoint_.same_rank_count())
      {
        IndexSet ghosts(discretization_.dof_handler().n_dofs());
        ghosts.add_indices(r.ghosts.begin(), r.ghosts.end());
        discretization_.add_ghost_dofs(ghosts);
      }
  }

  void
  Simulation::restore_state()
  {
    const std::string  key  = "N - Checkpoint/restart from";
    const unsigned int rank = Utilities::MPI::this_mpi_process(comm_);
    const bool         same = checkpoint_.same_rank_count();
    std::string        error;
    try
      {
        SavedGlobal                                 g;
        std::vector<SavedRank>                      ranks(checkpoint_.restart_ranks());
        std::vector<contact::Contact::PortableState> contact_states;
        for (unsigned int q = 0; q < ranks.size(); ++q)
          {
            base::BinaryReader reader(checkpoint_.payload(q));
            SavedGlobal        gq;
            read_payload(reader, q == 0 ? g : gq, ranks[q]);
            if (ranks[q].has_contact != contact_.active())
              throw std::runtime_error("contact is on in one of the checkpoint and this scene, off in the other");
            if (ranks[q].has_contact)
              {
                std::string exact;
                reader.get(exact);
                if (same && q == rank)
                  {
                    base::BinaryReader in(exact);
                    contact_.load(in);
                  }
                contact_states.emplace_back();
                contact_states.back().serialize([&](auto &x) { reader.get(x); });
              }
            reader.expect("end");
          }

        // Topology after the last rebuild: the bonds that broke since then.
        if (particles_.active())
          {
            std::vector<Bond> bonds;
            for (const auto &[a, b] : g.bonds)
              bonds.emplace_back(checkpoint_.node_of_key(a), checkpoint_.node_of_key(b));
            for (auto &b : bonds)
              if (b.first > b.second)
                std::swap(b.first, b.second);
            Keys free;
            for (const auto k : g.free)
              free.push_back(checkpoint_.node_of_key(k));
            particles_.break_bonds(bonds, free);
            particles_.take_rebuilt_rows();
            // The rows whose bond count the next breaking step looks at: as in the run at the
            // same partition; at another, every row (as after a rebuild of the particle set).
            if (same)
              particles_.restore_changed_rows(ranks[rank].changed_rows);
            bonds_.prepare(particles_, spg_, source_);
            fragments_stale_ = true;
          }
        bonds_.restore_counts(g.n_broken, g.n_free);

        // Nodes, elements and particles by key, from whichever rank wrote them.
        std::unordered_map<unsigned long long, std::pair<unsigned int, std::size_t>> node_at, particle_at;
        std::unordered_map<unsigned int, std::pair<unsigned int, std::size_t>>       element_at;
        for (unsigned int q = 0; q < ranks.size(); ++q)
          {
            for (std::size_t k = 0; k < ranks[q].node_keys.size(); ++k)
              node_at[ranks[q].node_keys[k]] = {q, k};
            for (std::size_t k = 0; k < ranks[q].cells.size(); ++k)
              element_at[ranks[q].cells[k]] = {q, k};
            for (std::size_t k = 0; k < ranks[q].particle_keys.size(); ++k)
              particle_at[ranks[q].particle_keys[k]] = {q, k};
          }
        const auto &pt = *discretization_.partitioner();
        for (unsigned int j = 0; j < pt.locally_owned_size(); j += 3)
          {
            const auto it = node_at.find(checkpoint_.key_of_local_dof(j));
            if (it == node_at.end())
              throw std::runtime_error("node " + std::to_string(checkpoint_.key_of_local_dof(j)) + " is missing");
            const double *x = &ranks[it->second.first].node_values[15 * it->second.second];
            for (auto *vec : {&d_, &v_, &v_now_, &f_, &f_ext_})
              for (unsigned int c = 0; c < 3; ++c, ++x)
                vec->local_element(j + c) = *x;
          }
        for (unsigned int e = 0; e < hex_.n_local_elements(); ++e)
          {
            const auto it = element_at.find(hex_.cell_index(e));
            if (it == element_at.end())
              throw std::runtime_error("element of cell " + std::to_string(hex_.cell_index(e)) + " is missing");
            const auto &s = ranks[it->second.first];
            const auto  k = it->second.second;
            if (!hex_.set_checkpoint_values(e, &s.element_values[s.element_offsets[k]],
                                            s.element_offsets[k + 1] - s.element_offsets[k]))
              throw std::runtime_error("element of cell " + std::to_string(hex_.cell_index(e)) +
                                       " has another number of history values");
          }
        for (unsigned int i = 0; i < spg_.n_owned(); ++i)
          {
            const auto key_i = checkpoint_.key_of_local_dof(particles_.local_dof(i));
            const auto it    = particle_at.find(key_i);
            if (it == particle_at.end())
              throw std::runtime_error("particle at node " + std::to_string(key_i) + " is missing");
            const auto   &s = ranks[it->second.first];
            const auto    k = it->second.second;
            const double *x = &s.particle_values[s.particle_offsets[k]];
            const unsigned int n_slots = spg_.material(i).n_state_slots();
            // stress (6), q, history, volume factor, residual offset (3)
            if (s.particle_offsets[k + 1] - s.particle_offsets[k] != 11 + n_slots)
              throw std::runtime_error("particle at node " + std::to_string(key_i) +
                                       " has another number of history values");
            spg_.set_state(i, x, x + 7, x[6]);
            spg_.set_volume_factor(i, x[7 + n_slots]);
            spg_.set_residual_offset(i, x + 8 + n_slots);
          }
        d_.update_ghost_values();
        v_.update_ghost_values();
        v_now_.update_ghost_values();
        const double stabilization = spg_.reset_deformation(d_);

        // Scalars: this rank's own at the same rank count; at another the sums on rank 0.
        std::vector<double> scalars = ranks[0].scalars;
        double              contact_energy = ranks[0].contact_energy;
        if (same)
          scalars = ranks[rank].scalars;
        else
          {
            for (unsigned int q = 1; q < ranks.size(); ++q)
              {
                for (unsigned int k = 0; k + 1 < scalars.size(); ++k)
                  scalars[k] += ranks[q].scalars[k];
                scalars.back() = std::min(scalars.back(), ranks[q].scalars.back());
                contact_energy += ranks[q].contact_energy;
              }
            if (rank != 0)
              {
                for (unsigned int k = 0; k + 1 < scalars.size(); ++k)
                  scalars[k] = 0;
                contact_energy = 0;
              }
            if (contact_.active())
              contact_.restore_portable(
                contact_states, [&](const unsigned long long key) { return checkpoint_.node_of_key(key); },
                contact_energy);
          }
        if (scalars.size() != 17)
          throw std::runtime_error("wrong number of scalars");
        internal_energy_ = scalars[0], hourglass_energy_ = scalars[1];
        stabilization_energy_ = same ? scalars[2] : stabilization;
        filter_work_ = scalars[3], conversion_elastic_ = scalars[4], bond_energy_ = scalars[5];
        balance_.kinetic = scalars[6];
        for (unsigned int c = 0; c < 3; ++c)
          balance_.momentum[c] = scalars[7 + c];
        balance_.external_work = scalars[10], balance_.boundary_work = scalars[11];
        balance_.pending_external = scalars[12], balance_.pending_boundary = scalars[13];
        element_steps_ = scalars[14], particle_steps_ = scalars[15], particle_dt_ = scalars[16];

        step_ = g.step, t_ = g.t, dt_ = g.dt, dt_next_ = g.dt_next, stable_dt_ = g.stable_dt;
        conversion_energy_ = g.conversion_energy, reference_energy_ = g.reference_energy;
        initial_energy_ = g.initial_energy, energy_error_ = g.energy_error, max_energy_error_ = g.max_energy_error;
        first_stable_dt_ = g.first_stable_dt, initial_max_speed_ = g.initial_max_speed;
        next_output_ = g.next_output, last_fragments_time_ = g.last_fragments_time;
        // 'K - Output/interval' may change on restart: a smaller interval than the checkpointed
        // run's (or one set where that run had 0) takes effect from here. With the same interval
        // this is a no-op: the checkpointed next output lies within one interval of t.
        if (output_.interval() > 0)
          next_output_ = std::min(next_output_, t_ + output_.interval());
        integrator_.set_held_dt(g.held_dt);
        q_final_ = g.q_final, q_min_ = g.q_min, q_max_ = g.q_max;
        output_.restore_records(g.records);
        fragments_started_ = g.fragments_started;
        history_bytes_ = g.history_bytes, fragments_bytes_ = g.fragments_bytes;
        history_hash_ = g.history_hash, fragments_hash_ = g.fragments_hash;
        if (rank == 0)
          truncate_tables();
      }
    catch (const std::exception &e)
      {
        error = e.what();
      }
    // Every rank fails together, with the first message.
    for (const auto &m : Utilities::MPI::all_gather(comm_, error))
      if (!m.empty())
        source_.fail(key, checkpoint_.restart_manifest(), "cannot restart from the checkpoint: " + m);
    if (rank == 0)
      std::fprintf(stderr, "shard: restart from %s: step %u, t = %.6e s (written at %u ranks)\n",
                   checkpoint_.restart_manifest().c_str(), step_, t_, checkpoint_.restart_ranks());
    checkpoint_.release();
  }

  void
  Simulation::truncate_tables() const
  {
    for (const auto &[name, bytes, hash] : {std::make_tuple(std::string("history.csv"), history_bytes_, history_hash_),
                                            std::make_tuple(std::string("fragments.csv"), fragments_bytes_, fragments_hash_)})
      {
        const std::string path = output_.directory() + "/" + name;
        if (!std::filesystem::exists(path))
          {
            if (bytes > 0)
              throw base::InputError("N - Checkpoint/restart from: " + path +
                                     " is missing; a restart continues the tables of the run that wrote the "
                                     "checkpoint (same K - Output/directory).");
            continue;
          }
        if (std::filesystem::file_size(path) < bytes)
          throw base::InputError("N - Checkpoint/restart from: " + path + " is shorter than at the checkpoint (" +
                                 std::to_string(bytes) + " bytes); it does not belong to this run.");
        if (base::fnv1a(file_head(path, bytes)) != hash)
          throw base::InputError("N - Checkpoint/restart from: the first " + std::to_string(bytes) + " bytes of " + path +
                                 " differ from those at the checkpoint (FNV-1a hash); it was changed since, or "
                                 "belongs to another run.");
        std::filesystem::resize_file(path, bytes);
      }
  }
} // namespace shard
