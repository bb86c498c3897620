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
#include <shard/output/quantities.h>
#include <shard/particles/bond_failure.h>
#include <shard/particles/particle_set.h>
#include <shard/particles/spg_force.h>
#include <shard/time/central_difference.h>

#include <array>
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

  private:
    MPI_Comm                     comm_;
    base::PrmSource              source_;
    dealii::ParameterHandler     prm_;
    std::string                  title_ = "shard scene";
    bool                         declared_ = false;

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

    // State vectors, all with the one layout of Discretization.
    mesh::Vector d_, v_, v_now_, f_, f_ext_, mass_, d_phys_;

    // Bookkeeping.
    time::LocalBalance balance_;
    double             internal_energy_ = 0, hourglass_energy_ = 0;
    double             stabilization_energy_ = 0, filter_work_ = 0;
    /// Energy changed by conversions (history averaging and the jump of the stabilization
    /// energy), summed over ranks (J); booked in the internal energy and as a source.
    double             conversion_energy_ = 0;
    /// Elastic part of conversion_energy_ on this rank (J), included in the internal energy.
    double             conversion_elastic_ = 0;
    /// Jump of the stabilization energy when bonds break, this rank (J); a source like the
    /// conversion energy.
    double             bond_energy_ = 0;
    /// Work space of the bond tests (normalized failure value and critical stretch per particle).
    mesh::Vector       bond_values_;
    double             reference_energy_ = 0, initial_energy_ = 0;
    double             energy_floor_ = 0; // 1e-14 M c^2: the smallest reference of the energy error
    double             t_ = 0, dt_ = 0, dt_next_ = 0, stable_dt_ = 0;
    unsigned int       step_ = 0;
    unsigned int       physical_step_ = ~0u;
    double             energy_error_ = 0, max_energy_error_ = 0;
    std::vector<double> q_final_, q_min_, q_max_;
    std::ofstream      history_;
    std::array<double, 11> phase_time_{};
    /// Element and particle force evaluations on this rank (summed over steps), and their
    /// sums over ranks after the run, for the per-step rates.
    double                element_steps_ = 0, particle_steps_ = 0;
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

    void
    record();
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
    /// "; <condition>/function = ... is not finite: ..." for a non-finite row, or "". Collective.
    std::string
    non_finite_source() const;
    std::string        pending_rows_; // history rows recorded before history.csv is opened (step 0)
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
    /// Global stable step before the first step, and the particles' own step of the last force
    /// evaluation (s).
    double first_stable_dt_ = 0, particle_dt_ = 1e300;
    /// The diagnostic of a collapsed step: the step, the limit and the element or particle with
    /// the smallest step on any rank. @note Collective.
    std::string
    collapsed_step_message() const;
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
    void
    write_summary(const RunResult &result, double wall_time) const;
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
