// SPDX-License-Identifier: LGPL-2.1-or-later
/**
 * @file simulation.h
 * @brief The owner of every component and the explicit time loop.
 * @ingroup simulation
 */
#pragma once

#include <shard/base/parameters.h>
#include <shard/bc/boundary_conditions.h>
#include <shard/contact/contact.h>
#include <shard/coupling/conversion.h>
#include <shard/fe/hex_force.h>
#include <shard/materials/material_library.h>
#include <shard/output/checkpoint.h>
#include <shard/mesh/discretization.h>
#include <shard/output/field_output.h>
#include <shard/output/fragments.h>
#include <shard/output/history.h>
#include <shard/output/quantities.h>
#include <shard/base/progress.h>
#include <shard/simulation/energy_balance.h>
#include <shard/simulation/explicit_step.h>
#include <shard/particles/bond_failure.h>
#include <shard/particles/particle_set.h>
#include <shard/particles/spg_force.h>
#include <shard/time/central_difference.h>

#include <array>
#include <chrono>
#include <cstdint>
#include <fstream>
#include <string>
#include <vector>

namespace shard
{
  /// Outcome of a run.
  struct RunResult
  {
    /// "completed", "max steps reached" or "unstable".
    std::string status;
    /// Diagnostic of an unstable run.
    std::string message;
    /// Exit code for the program: 0 completed, 3 unstable.
    int exit_code = 0;
    /// False when the run stopped at step 0, before it wrote anything into its output directory.
    bool wrote_output = true;
  };

  /**
   * @brief A scene: owns every component by value in dependency order (subsection
   * `A - Simulation` for its own keys) and runs the explicit step.
   *
   * Construction declares nothing; read() declares and parses all parameters, prepare()
   * builds, run() integrates. run() reads as the numbered phases of the step
   * (doc/manual/time_loop.md).
   */
  class Simulation : public base::ParameterOwner
  {
  public:
    /// @param comm communicator of the run.
    explicit Simulation(MPI_Comm comm);

    bool
    declare_parameters(dealii::ParameterHandler &prm) override;

    void
    check_parameters(const base::PrmSource &source) const override;

    /**
     * @brief Declares, parses and checks the parameters of every component.
     * @throws base::InputError naming key, file line and allowed range.
     */
    void
    read(const base::PrmSource &source);

    /// Writes every parameter with its documentation, in declaration order.
    void
    print_parameters(std::ostream &out) const;

    /**
     * @brief Builds mesh, DOFs, materials, element arrays and the initial state.
     * @throws base::InputError for inputs that can only be checked while building (mesh files).
     * @note Collective.
     */
    void
    prepare();

    /**
     * @brief Integrates to the end time; writes history.csv, field output and summary.json.
     * @note Collective.
     */
    RunResult
    run();

    /// Output directory of the run.
    const std::string &
    output_directory() const
    {
      return output_.directory();
    }

    /// The field series a user opens in ParaView (solution.pvd, or solution.xdmf with hdf5).
    std::string
    field_series() const
    {
      return output_.series_path();
    }

  private:
    MPI_Comm                     comm_;
    base::PrmSource              source_;
    dealii::ParameterHandler     prm_;
    std::string                  title_ = "shard scene";

    // Components in dependency order.
    mesh::Discretization         discretization_;
    materials::MaterialLibrary   materials_;
    particles::ParticleSet       particles_;
    particles::BondFailure       bonds_;
    coupling::Conversion         conversion_;
    contact::Contact             contact_;
    fe::HexForce                 hex_;
    particles::SpgForce          spg_;
    bc::BoundaryConditions       conditions_;
    time::CentralDifference      integrator_;
    output::FieldOutput          output_;
    output::Quantities           quantities_;
    output::Fragments            fragments_;
    output::Checkpoint           checkpoint_;

    // What the loop advances, the energy accounts, the timers and the history table.
    StepState            state_;
    EnergyBalance        energy_;
    base::PhaseTimes     times_;
    output::HistoryTable history_;
    /// The phases 1 to 9 of the step (phase 10, record, is below).
    ExplicitStep explicit_step_;

    unsigned int       physical_step_ = ~0u;
    std::vector<double> q_final_, q_min_, q_max_;
    /// Element and particle force evaluations summed over ranks after the run.
    std::array<double, 2> work_steps_{};
    /// Partition (doc/performance.md, MPI scaling): owned elements and particles per rank at
    /// set-up, the work imbalance max/mean of (elements + particle weight x particles) after
    /// the weighted repartition, and the predicted imbalance of the cell-count partition
    /// before it (0: not repartitioned).
    std::vector<double> rank_elements_, rank_particles_;
    double              imbalance_ = 1, imbalance_before_ = 0;

    /// Gathers rank_elements_, rank_particles_ and imbalance_ (collective).
    void
    measure_partition();

    /// Phase 10 for one history row: reduces the energy terms, evaluates the quantities, adds
    /// the row and stops the run if a value is not finite or the energy error exceeds its limit.
    void
    record();
    /// Initial state (no restart): K0, kinematic conditions at t = 0, the first kick and the
    /// step-0 row. @return false if step 0 failed its checks (nothing written). @note Collective.
    bool
    start(RunResult &result);
    /// Opens history.csv, writes parameters.prm and, for a new run, the output of step 0.
    void
    open_output(bool restarted);
    /// Phase 10 of a step: history row, fields, progress line, checkpoint. @return @p last.
    bool
    record_step(bool last, RunResult &result);
    /// Whether the run has reached the end time or the step limit.
    bool
    at_end() const;
    /// Sets the status "max steps reached" when the step limit stopped the run before the end time.
    void
    record_status(RunResult &result) const;
    /// After the loop: fragment statistics, plots, summary.json and the phase table.
    void
    finish(const RunResult &result, double wall_time);
    /// fragment_statistics.csv of the last fragments (rank 0).
    void
    write_fragment_statistics() const;
    /// Progress of the loop: wall clock and pace of the last progress line.
    struct Progress
    {
      std::chrono::steady_clock::time_point last, loop_start;
      double                                start_time = 0;
      base::ProgressEstimate                pace;
    } progress_;
    /// Stops with an input error if a rigid body is (or may become) particles. @note Collective.
    void
    check_rigid_bodies() const;

    /// Simulated time of the next field output (s).
    double next_output_ = 0;
    /// Text of everything a checkpoint must agree on: the parameters except end time, max
    /// steps, title, output and checkpoint keys, and the mesh size.
    std::string
    fingerprint() const;
    /**
     * @brief Phase 10, checkpoint: everything that determines the future of the run, this
     * rank's share keyed by partition-independent ids (doc/manual/checkpoint.md), written
     * atomically by Checkpoint. @note Collective.
     */
    void
    write_checkpoint();
    /// Restart, before the particle set is built: converted cells, the broken bonds of the
    /// last rebuild and (same rank count) the ghost set of the checkpoint.
    void
    restore_topology();
    /// Restart, after prepare(): the state of the checkpoint. @note Collective.
    void
    restore_state();
    /// Restart: history.csv and fragments.csv cut back to the checkpoint (rank 0).
    void
    truncate_tables() const;
    /// Sizes of history.csv and fragments.csv at the checkpoint read (bytes).
    unsigned long long history_bytes_ = 0, fragments_bytes_ = 0;
    std::uint64_t      history_hash_ = 0, fragments_hash_ = 0; // FNV-1a of those bytes at the checkpoint
    /// The fastest node or particle of all ranks, for the energy-limit diagnostic.
    struct FastestNode
    {
      double                speed = 0, initial_speed = 0;
      std::string           body;
      bool                  particle = false;
      /// Global node id (global DOF / 3; for a particle its global particle id).
      unsigned long long    id = 0;
      /// Current position X + d (m).
      std::array<double, 3> position{};
      /// "fastest node N of body 'b' at (x, y, z) m: speed S m/s (largest initial speed S0 m/s)".
      std::string
      describe() const;
    };
    /// @note Collective.
    FastestNode
    fastest_node(const mesh::Vector &v) const;
    /// Largest speed of the input velocity field, before the kinematic conditions at t = 0 (m/s).
    double initial_max_speed_ = 0;
    /**
     * @brief Converts the local elements @p elements of every rank to particles at the end of
     * a step: history transfer, particle set, stencils and ghost set rebuilt, vectors moved to
     * the new layout (phase 4b, doc/manual/hybrid.md).
     * @note Collective.
     */
    void
    convert(const std::vector<unsigned int> &elements);
    /// Physical displacement for output and quantities: d, with u = A d at the particles
    /// (assembled once per step, then reused by the history row and the field output).
    const mesh::Vector &
    physical_displacement();
    /// Gathers the memory, timing and partition figures of all ranks and (rank 0) fills an
    /// output::RunSummary and writes it to summary.json (output::write_run_summary_file()).
    /// @note Collective.
    void
    write_summary(const RunResult &result, double wall_time, const base::PhaseTimes::Times &max_time) const;
    /// With particles: appends the fragments now to fragments.csv and keeps them for the
    /// statistics at the end (doc/manual/hybrid.md, "Fragments"). @note Collective.
    void
    write_fragments();
    /// The fragments of the last write_fragments() (empty without particles).
    std::vector<output::Fragment> last_fragments_;
    double                        last_fragments_time_ = -1;
    bool                          fragments_started_   = false;
    /// Bonds broke since Fragments::prepare() (it is redone at the next fragment output).
    bool                          fragments_stale_     = false;
  };
} // namespace shard
