// SPDX-License-Identifier: LGPL-2.1-or-later
/**
 * @file phase_timer.h
 * @brief Wall and CPU time per phase of the explicit step, and the phase table of a run.
 * @ingroup base
 */
#pragma once

#include <mpi.h>

#include <algorithm>
#include <array>
#include <chrono>
#include <cstdio>

namespace shard::base
{
  /// The phases of the explicit step (doc/manual/time_loop.md); the value is the phase number.
  enum class Phase : unsigned int
  {
    setup          = 0,
    step_size      = 1,
    drift          = 2,
    exchange       = 3,
    topology       = 4,
    fe_force       = 5,
    particle_force = 6,
    loads          = 7,
    accumulate     = 8,
    kick           = 9,
    record         = 10
  };

  /**
   * @brief Wall time and CPU time of the calling thread, summed per phase of the step.
   *
   * The wall times are what the phase table and `phase_time_s` of summary.json report (largest
   * over ranks). The CPU times (`phase_cpu_time_by_rank_s`) show the work of a phase without the
   * time the rank was descheduled, which is what an oversubscribed machine can measure
   * (doc/performance.md, MPI scaling).
   */
  class PhaseTimes
  {
  public:
    static constexpr unsigned int n_phases = 11;
    using Times                            = std::array<double, n_phases>;

    /// "0 set-up", "1 step size", ...: the names of summary.json and the phase table.
    static const std::array<const char *, n_phases> &
    names();

    /// Adds the wall and CPU time of its lifetime to one phase.
    class Scope
    {
    public:
      Scope(PhaseTimes &times, Phase phase);
      ~Scope();
      Scope(const Scope &) = delete;
      Scope &
      operator=(const Scope &) = delete;

    private:
      PhaseTimes                           &times_;
      unsigned int                          phase_;
      std::chrono::steady_clock::time_point start_;
      double                                cpu_start_;
    };

    /// A scope timing @p phase.
    Scope
    scope(const Phase phase)
    {
      return Scope(*this, phase);
    }

    /// Adds @p wall seconds of wall time and @p cpu seconds of CPU time to @p phase (the
    /// set-up, timed before the loop exists).
    void
    add(const Phase phase, const double wall, const double cpu)
    {
      wall_[static_cast<unsigned int>(phase)] += wall;
      cpu_[static_cast<unsigned int>(phase)] += cpu;
    }

    /// Zeroes the CPU times of the step phases at the start of a run (the phases timed inside
    /// the set-up are part of the set-up's time); the set-up's wall and CPU time are kept.
    void
    reset_cpu()
    {
      std::fill(cpu_.begin() + 1, cpu_.end(), 0.);
    }

    /// CPU time of the calling thread since it started (s): what Scope measures.
    static double
    thread_cpu_time();

    /// This rank's wall time per phase (s).
    const Times &
    wall() const
    {
      return wall_;
    }

    /// This rank's CPU time of the main thread per phase (s).
    const Times &
    cpu() const
    {
      return cpu_;
    }

    /// The largest wall time of every phase over the ranks of @p comm (s). @note Collective.
    Times
    max_wall(MPI_Comm comm) const;

    /**
     * @brief Prints the phase table (largest over ranks, share of the loop) and the throughput
     * of the force phases to @p out.
     * @param max_wall      the result of max_wall()
     * @param n_threads     threads per rank, for the heading
     * @param element_steps element force evaluations of the run, summed over ranks
     * @param particle_steps particle force evaluations of the run, summed over ranks
     */
    static void
    print_table(std::FILE *out, const Times &max_wall, unsigned int n_threads, double element_steps,
                double particle_steps);

  private:
    Times wall_{};
    Times cpu_{};
  };

} // namespace shard::base
