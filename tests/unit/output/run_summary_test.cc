// SPDX-License-Identifier: LGPL-2.1-or-later
// RunSummary (output/run_summary.h): summary.json text against expected text written by hand:
// key order, 10 significant digits, null for non-finite reals, optional message and fragment
// block, escaping, and the atomic file writer.
#include <shard/output/run_summary.h>

#include <unistd.h>

#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <iomanip>
#include <limits>
#include <sstream>
#include <string>

namespace
{
  using shard::output::RunSummary;

  /// A summary with every member set to a distinct value, no message and no fragments.
  RunSummary
  example()
  {
    RunSummary s;
    s.version              = "0.1.0 (abc1234)";
    s.title                = "Taylor bar";
    s.parameter_file       = "bar.prm";
    s.status               = "completed";
    s.steps                = 1200;
    s.final_time           = 2.5e-5;
    s.last_dt              = 1.0 / 48000000;
    s.wall_time            = 12.25;
    s.n_elements           = 4096;
    s.n_particles          = 729;
    s.n_converted_elements = 7;
    s.conversion_events    = 2;
    s.conversion_energy    = 0.125;
    s.broken_bonds         = 31;
    s.free_particles       = 3;
    s.contact_rebuilds     = 5;
    s.correction_iterations = 41;
    s.n_mpi_ranks           = 2;
    s.n_threads             = 1;
    s.energy_error          = -1.5e-4;
    s.max_abs_energy_error  = 3e-3;
    s.element_steps_per_s   = 1234567.891;
    s.us_per_element_step   = 0.81;
    s.particle_steps_per_s  = 0;
    s.us_per_particle_step  = 0;
    s.particle_bytes        = 1048576;
    s.bytes_per_particle    = 1438.375;
    s.n_dofs                = 14739;
    s.vector_bytes          = 2e6;
    s.vector_bytes_per_dof  = 135.6944444444444;
    s.element_bytes         = 524288;
    s.bytes_per_element     = 128;
    s.peak_rss_bytes        = 123456789012.;
    s.partition             = {2.5, {2048, 2048}, {729, 0}, 1.25, 1.5};
    s.phase_time_by_rank     = {{0.5, 1}, {0.25, 2}};
    s.phase_cpu_time_by_rank = {{0.5, 1.5}, {0.75, 2}};
    s.phase_time             = {{"0 set-up", 0.5}, {"1 step size", 2}};
    s.memory_by_rank         = {{"mesh", {1024, 2048}}, {"peak resident", {3e8, 2.5e8}}};
    s.bytes_sent_per_step_by_rank = {{"3 ghost values", {96, 48}}, {"8 ghost sums", {0.5, 0}}};
    s.results                = {{"tip", 1e-3, -2e-3, 4e-3}, {"r", 7, 6, 8}};
    s.history_file           = "out/history.csv";
    s.field_file             = "out/fields.pvd";
    s.parameter_copy         = "out/parameters.prm";
    return s;
  }

  std::string
  text(const RunSummary &s)
  {
    std::ostringstream out;
    shard::output::write_run_summary(s, out);
    return out.str();
  }

  const std::string head = "{\n"
                           "  \"shard_version\": \"0.1.0 (abc1234)\",\n"
                           "  \"title\": \"Taylor bar\",\n"
                           "  \"parameter_file\": \"bar.prm\",\n";
  const std::string counts = "  \"steps\": 1200,\n"
                             "  \"final_time\": 2.5e-05,\n"
                             "  \"last_dt\": 2.083333333e-08,\n"
                             "  \"wall_time_s\": 12.25,\n"
                             "  \"n_elements\": 4096,\n"
                             "  \"n_particles\": 729,\n"
                             "  \"n_converted_elements\": 7,\n"
                             "  \"conversion_events\": 2,\n"
                             "  \"conversion_energy\": 0.125,\n"
                             "  \"broken_bonds\": 31,\n"
                             "  \"free_particles\": 3,\n"
                             "  \"contact_rebuilds\": 5,\n";
  const std::string tail =
    "  \"correction_iterations\": 41,\n"
    "  \"n_mpi_ranks\": 2,\n"
    "  \"n_threads\": 1,\n"
    "  \"energy_error\": -0.00015,\n"
    "  \"max_abs_energy_error\": 0.003,\n"
    "  \"element_steps_per_s\": 1234567.891,\n"
    "  \"us_per_element_step\": 0.81,\n"
    "  \"particle_steps_per_s\": 0,\n"
    "  \"us_per_particle_step\": 0,\n"
    "  \"particle_bytes\": 1048576,\n"
    "  \"bytes_per_particle\": 1438.375,\n"
    "  \"n_dofs\": 14739,\n"
    "  \"vector_bytes\": 2000000,\n"
    "  \"vector_bytes_per_dof\": 135.6944444,\n"
    "  \"element_bytes\": 524288,\n"
    "  \"bytes_per_element\": 128,\n"
    "  \"peak_rss_bytes\": 1.23456789e+11,\n"
    "  \"partition\": {\"particle_weight\": 2.5, \"elements_per_rank\": [2048, 2048], \"particles_per_rank\": "
    "[729, 0], \"work_imbalance\": 1.25, \"work_imbalance_cell_count\": 1.5},\n"
    "  \"phase_time_by_rank_s\": [[0.5, 1], [0.25, 2]],\n"
    "  \"phase_cpu_time_by_rank_s\": [[0.5, 1.5], [0.75, 2]],\n"
    "  \"phase_time_s\": {\"0 set-up\": 0.5, \"1 step size\": 2},\n"
    "  \"memory_by_rank_bytes\": {\"mesh\": [1024, 2048], \"peak resident\": [300000000, 250000000]},\n"
    "  \"bytes_sent_per_step_by_rank\": {\"3 ghost values\": [96, 48], \"8 ghost sums\": [0.5, 0]},\n"
    "  \"results\": {\"tip\": 0.001, \"tip_min\": -0.002, \"tip_max\": 0.004, \"r\": 7, \"r_min\": 6, \"r_max\": 8},\n"
    "  \"files\": {\"history\": \"out/history.csv\", \"fields\": \"out/fields.pvd\", \"parameters\": "
    "\"out/parameters.prm\"}\n"
    "}\n";
} // namespace

TEST(RunSummary, KeysInOrderWithTenDigits)
{
  EXPECT_EQ(text(example()), head + "  \"status\": \"completed\",\n" + counts + tail);
}

TEST(RunSummary, MessageAndFragmentsOnlyWhenSet)
{
  auto s            = example();
  s.status          = "unstable";
  s.message         = "element 12: \"J < 0\"\nat step 3";
  s.fragments.count = 2;
  s.fragments.total_mass   = 3.0;
  s.fragments.largest_mass = 2.0 / 3;
  s.fragments.json         = "{\"debris\": 1}";
  const std::string fragments = "  \"n_fragments\": 2,\n"
                                "  \"fragment_mass_total\": 3,\n"
                                "  \"largest_fragment_mass\": 0.6666666667,\n"
                                "  \"fragments\": {\"debris\": 1},\n";
  EXPECT_EQ(text(s), head + "  \"status\": \"unstable\",\n" +
                       "  \"message\": \"element 12: \\\"J < 0\\\"\\nat step 3\",\n" + counts + fragments + tail);
}

TEST(RunSummary, NonFiniteRealsAreNull)
{
  auto s                  = example();
  s.energy_error          = std::numeric_limits<double>::quiet_NaN();
  s.max_abs_energy_error  = std::numeric_limits<double>::infinity();
  s.results               = {{"x", -std::numeric_limits<double>::infinity(), 0, 1}};
  s.phase_time_by_rank    = {};
  s.phase_cpu_time_by_rank = {{}};
  const std::string out   = text(s);
  EXPECT_NE(out.find("  \"energy_error\": null,\n  \"max_abs_energy_error\": null,\n"), std::string::npos);
  EXPECT_NE(out.find("  \"results\": {\"x\": null, \"x_min\": 0, \"x_max\": 1},\n"), std::string::npos);
  EXPECT_NE(out.find("  \"phase_time_by_rank_s\": [],\n  \"phase_cpu_time_by_rank_s\": [[]],\n"), std::string::npos);
}

TEST(RunSummary, StreamStateDoesNotMatter)
{
  std::ostringstream out;
  out << std::setprecision(3) << std::scientific << std::hex << std::showpos;
  shard::output::write_run_summary(example(), out);
  EXPECT_EQ(out.str(), head + "  \"status\": \"completed\",\n" + counts + tail);
}

TEST(RunSummary, FileWriter)
{
  const auto path = std::filesystem::temp_directory_path() / ("shard_run_summary_test_" + std::to_string(::getpid()) + ".json");
  shard::output::write_run_summary_file(example(), path.string());
  std::ifstream     in(path);
  std::stringstream s;
  s << in.rdbuf();
  EXPECT_EQ(s.str(), head + "  \"status\": \"completed\",\n" + counts + tail);
  std::filesystem::remove(path);
}
