// SPDX-License-Identifier: LGPL-2.1-or-later
/**
 * @file run_summary.h
 * @brief summary.json: the values of a finished run (RunSummary) and their JSON text.
 * @ingroup output
 */
#pragma once

#include <ostream>
#include <string>
#include <utility>
#include <vector>

namespace shard::output
{
  /**
   * @brief What summary.json reports about a run, filled by Simulation::write_summary() and
   * written by write_run_summary(). Every member is the value written (no reduction or ratio is
   * formed by the writer). Reals are written with 10 significant digits, `null` when not
   * finite; counts as integers; strings JSON-escaped.
   */
  struct RunSummary
  {
    /// `shard_version`: "version (git description)".
    std::string version;
    /// `title` of the scene.
    std::string title;
    /// `parameter_file`: the .prm file of the run.
    std::string parameter_file;
    /// `status`: "completed", "max steps reached" or "unstable".
    std::string status;
    /// `message`: the diagnostic of an unstable run; not written when empty.
    std::string message;
    /// `steps` taken.
    unsigned long long steps = 0;
    /// `final_time` (s) and `last_dt`, the last step (s).
    double final_time = 0, last_dt = 0;
    /// `wall_time_s`: the wall time of the run (s).
    double wall_time = 0;
    /// `n_elements` (active cells of all bodies) and `n_particles` (all ranks).
    unsigned long long n_elements = 0, n_particles = 0;
    /// `n_converted_elements` and `conversion_events`.
    unsigned long long n_converted_elements = 0, conversion_events = 0;
    /// `conversion_energy` (J).
    double conversion_energy = 0;
    /// `broken_bonds`, `free_particles` and `contact_rebuilds`.
    unsigned long long broken_bonds = 0, free_particles = 0, contact_rebuilds = 0;
    /// `known_broken_bonds_by_rank` and `known_free_particles_by_rank`: the lengths of the
    /// lists each rank keeps (ParticleSet::broken_bonds(), free_particles()); a rank knows the
    /// bonds and free particles near its rows, not all (written when bonds broke).
    std::vector<double> known_broken_bonds_by_rank, known_free_particles_by_rank;
    /// `particle_table_rows_by_rank`: the particle rows each rank built its stencils from
    /// (ParticleSet::table_rows(); written when there are particles).
    std::vector<double> particle_table_rows_by_rank;

    /// The fragment block, written only when there are fragments.
    struct Fragments
    {
      /// `n_fragments`; 0: the block is not written.
      unsigned long long count = 0;
      /// `fragment_mass_total` and `largest_fragment_mass` (kg).
      double total_mass = 0, largest_mass = 0;
      /// `fragments`: the JSON object of output::summary_json(), written as it is.
      std::string json;
    } fragments;

    /// `correction_iterations` of the consistent correction solve.
    unsigned long long correction_iterations = 0;
    /// `n_mpi_ranks` and `n_threads` (per rank).
    unsigned long long n_mpi_ranks = 0, n_threads = 0;
    /// `energy_error` and `max_abs_energy_error` (1).
    double energy_error = 0, max_abs_energy_error = 0;
    /// `element_steps_per_s` and `us_per_element_step`.
    double element_steps_per_s = 0, us_per_element_step = 0;
    /// `particle_steps_per_s` and `us_per_particle_step`.
    double particle_steps_per_s = 0, us_per_particle_step = 0;
    /// `particle_bytes` (all ranks) and `bytes_per_particle`.
    double particle_bytes = 0, bytes_per_particle = 0;
    /// `n_dofs`.
    unsigned long long n_dofs = 0;
    /// `vector_bytes` (all ranks) and `vector_bytes_per_dof`.
    double vector_bytes = 0, vector_bytes_per_dof = 0;
    /// `element_bytes` (all ranks) and `bytes_per_element`.
    double element_bytes = 0, bytes_per_element = 0;
    /// `peak_rss_bytes` (largest over ranks).
    double peak_rss_bytes = 0;

    /// The `partition` object.
    struct Partition
    {
      /// `particle_weight`: the work of a particle in elements.
      double particle_weight = 0;
      /// `elements_per_rank` and `particles_per_rank`.
      std::vector<double> elements_per_rank, particles_per_rank;
      /// `work_imbalance` and `work_imbalance_cell_count` (1).
      double work_imbalance = 0, work_imbalance_cell_count = 0;
    } partition;

    /// `phase_time_by_rank_s` and `phase_cpu_time_by_rank_s`: per rank, the time of every phase (s).
    std::vector<std::vector<double>> phase_time_by_rank, phase_cpu_time_by_rank;
    /// `phase_time_s`: phase name and its time (s), in order.
    std::vector<std::pair<std::string, double>> phase_time;
    /// `bytes_sent_per_step_by_rank`: per exchange point (base::Traffic), the mean bytes each
    /// rank sent per step.
    std::vector<std::pair<std::string, std::vector<double>>> bytes_sent_per_step_by_rank;
    /// `memory_by_rank_bytes`: per part (mesh, DoF handler, particles, ..., resident set at the
    /// end and its peak), the bytes on each rank: which parts grow with the model, not the rank.
    std::vector<std::pair<std::string, std::vector<double>>> memory_by_rank;

    /// One quantity of `results`: `name`, `name_min` and `name_max`.
    struct Result
    {
      std::string name;
      double      final = 0, min = 0, max = 0;
    };
    /// `results`, in column order.
    std::vector<Result> results;

    /// The `files` object: paths of history.csv, the field output (.pvd) and parameters.prm.
    std::string history_file, field_file, parameter_copy;
  };

  /**
   * @brief Writes @p summary as summary.json text to @p out: one key per line, in a fixed order
   * (the order of the RunSummary members), ending with a newline. The state of @p out
   * (precision, flags) does not matter.
   */
  void
  write_run_summary(const RunSummary &summary, std::ostream &out);

  /**
   * @brief Writes @p summary to @p path atomically (base::write_file_atomically()).
   * @throws std::runtime_error if the file cannot be written.
   */
  void
  write_run_summary_file(const RunSummary &summary, const std::string &path);
} // namespace shard::output
