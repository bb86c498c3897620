// SPDX-License-Identifier: LGPL-2.1-or-later
#include <shard/base/parameters.h>
#include <shard/output/run_summary.h>

#include <cmath>
#include <iomanip>
#include <sstream>

namespace shard::output
{
  namespace
  {
    /// A real with 10 significant digits; `null` when not finite.
    std::string
    number(const double x)
    {
      if (!std::isfinite(x))
        return "null";
      std::ostringstream s;
      s << std::setprecision(10) << x;
      return s.str();
    }

    /// A JSON list of reals: "[a, b, c]".
    std::string
    list(const std::vector<double> &x)
    {
      std::string out;
      for (unsigned int r = 0; r < x.size(); ++r)
        out += (r ? ", " : "") + number(x[r]);
      return "[" + out + "]";
    }

    /// A JSON string.
    std::string
    text(const std::string &s)
    {
      return "\"" + base::json_escape(s) + "\"";
    }

    /// The run: version, scene, status, counts, time, conversion, bonds, contact.
    void
    write_run(const RunSummary &s, std::ostream &j)
    {
      j << "  \"shard_version\": " << text(s.version) << ",\n";
      j << "  \"title\": " << text(s.title) << ",\n";
      j << "  \"parameter_file\": " << text(s.parameter_file) << ",\n";
      j << "  \"status\": " << text(s.status) << ",\n";
      if (!s.message.empty())
        j << "  \"message\": " << text(s.message) << ",\n";
      j << "  \"steps\": " << s.steps << ",\n";
      j << "  \"final_time\": " << number(s.final_time) << ",\n";
      j << "  \"last_dt\": " << number(s.last_dt) << ",\n";
      j << "  \"wall_time_s\": " << number(s.wall_time) << ",\n";
      j << "  \"n_elements\": " << s.n_elements << ",\n";
      j << "  \"n_particles\": " << s.n_particles << ",\n";
      j << "  \"n_converted_elements\": " << s.n_converted_elements << ",\n";
      j << "  \"conversion_events\": " << s.conversion_events << ",\n";
      j << "  \"conversion_energy\": " << number(s.conversion_energy) << ",\n";
      j << "  \"broken_bonds\": " << s.broken_bonds << ",\n";
      j << "  \"free_particles\": " << s.free_particles << ",\n";
      if (!s.particle_table_rows_by_rank.empty())
        j << "  \"particle_table_rows_by_rank\": " << list(s.particle_table_rows_by_rank) << ",\n";
      if (s.broken_bonds + s.free_particles > 0 && !s.known_broken_bonds_by_rank.empty())
        {
          j << "  \"known_broken_bonds_by_rank\": " << list(s.known_broken_bonds_by_rank) << ",\n";
          j << "  \"known_free_particles_by_rank\": " << list(s.known_free_particles_by_rank) << ",\n";
        }
      j << "  \"contact_rebuilds\": " << s.contact_rebuilds << ",\n";
      if (s.fragments.count > 0)
        {
          j << "  \"n_fragments\": " << s.fragments.count << ",\n";
          j << "  \"fragment_mass_total\": " << number(s.fragments.total_mass) << ",\n";
          j << "  \"largest_fragment_mass\": " << number(s.fragments.largest_mass) << ",\n";
          j << "  \"fragments\": " << s.fragments.json << ",\n";
        }
      j << "  \"correction_iterations\": " << s.correction_iterations << ",\n";
      j << "  \"n_mpi_ranks\": " << s.n_mpi_ranks << ",\n";
      j << "  \"n_threads\": " << s.n_threads << ",\n";
      j << "  \"energy_error\": " << number(s.energy_error) << ",\n";
      j << "  \"max_abs_energy_error\": " << number(s.max_abs_energy_error) << ",\n";
    }

    /// Throughput and memory.
    void
    write_performance(const RunSummary &s, std::ostream &j)
    {
      j << "  \"element_steps_per_s\": " << number(s.element_steps_per_s) << ",\n";
      j << "  \"us_per_element_step\": " << number(s.us_per_element_step) << ",\n";
      j << "  \"particle_steps_per_s\": " << number(s.particle_steps_per_s) << ",\n";
      j << "  \"us_per_particle_step\": " << number(s.us_per_particle_step) << ",\n";
      j << "  \"particle_bytes\": " << number(s.particle_bytes) << ",\n";
      j << "  \"bytes_per_particle\": " << number(s.bytes_per_particle) << ",\n";
      j << "  \"n_dofs\": " << s.n_dofs << ",\n";
      j << "  \"vector_bytes\": " << number(s.vector_bytes) << ",\n";
      j << "  \"vector_bytes_per_dof\": " << number(s.vector_bytes_per_dof) << ",\n";
      j << "  \"element_bytes\": " << number(s.element_bytes) << ",\n";
      j << "  \"bytes_per_element\": " << number(s.bytes_per_element) << ",\n";
      j << "  \"peak_rss_bytes\": " << number(s.peak_rss_bytes) << ",\n";
      const auto &p = s.partition;
      j << "  \"partition\": {\"particle_weight\": " << number(p.particle_weight)
        << ", \"elements_per_rank\": " << list(p.elements_per_rank)
        << ", \"particles_per_rank\": " << list(p.particles_per_rank)
        << ", \"work_imbalance\": " << number(p.work_imbalance)
        << ", \"work_imbalance_cell_count\": " << number(p.work_imbalance_cell_count) << "},\n";
      j << "  \"phase_time_by_rank_s\": [";
      for (unsigned int r = 0; r < s.phase_time_by_rank.size(); ++r)
        j << (r ? ", " : "") << list(s.phase_time_by_rank[r]);
      j << "],\n";
      j << "  \"phase_cpu_time_by_rank_s\": [";
      for (unsigned int r = 0; r < s.phase_cpu_time_by_rank.size(); ++r)
        j << (r ? ", " : "") << list(s.phase_cpu_time_by_rank[r]);
      j << "],\n";
      j << "  \"phase_time_s\": {";
      for (unsigned int p = 0; p < s.phase_time.size(); ++p)
        j << (p ? ", " : "") << text(s.phase_time[p].first) << ": " << number(s.phase_time[p].second);
      j << "},\n";
      j << "  \"memory_by_rank_bytes\": {";
      for (unsigned int p = 0; p < s.memory_by_rank.size(); ++p)
        j << (p ? ", " : "") << text(s.memory_by_rank[p].first) << ": " << list(s.memory_by_rank[p].second);
      j << "},\n";
      j << "  \"bytes_sent_per_step_by_rank\": {";
      for (unsigned int p = 0; p < s.bytes_sent_per_step_by_rank.size(); ++p)
        j << (p ? ", " : "") << text(s.bytes_sent_per_step_by_rank[p].first) << ": "
          << list(s.bytes_sent_per_step_by_rank[p].second);
      j << "},\n";
    }

    /// The quantities of interest and the files of the run.
    void
    write_results(const RunSummary &s, std::ostream &j)
    {
      j << "  \"results\": {";
      for (unsigned int i = 0; i < s.results.size(); ++i)
        {
          const auto &r = s.results[i];
          j << (i ? ", " : "") << text(r.name) << ": " << number(r.final) << ", " << text(r.name + "_min") << ": "
            << number(r.min) << ", " << text(r.name + "_max") << ": " << number(r.max);
        }
      j << "},\n";
      j << "  \"files\": {\"history\": " << text(s.history_file) << ", \"fields\": " << text(s.field_file)
        << ", \"parameters\": " << text(s.parameter_copy) << "}\n";
    }
  } // namespace

  void
  write_run_summary(const RunSummary &summary, std::ostream &out)
  {
    std::ostringstream j;
    j << "{\n";
    write_run(summary, j);
    write_performance(summary, j);
    write_results(summary, j);
    j << "}\n";
    out << j.str();
  }

  void
  write_run_summary_file(const RunSummary &summary, const std::string &path)
  {
    std::ostringstream j;
    write_run_summary(summary, j);
    base::write_file_atomically(path, j.str());
  }
} // namespace shard::output
