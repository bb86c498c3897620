// SPDX-License-Identifier: LGPL-2.1-or-later
#include <shard/base/phase_timer.h>

#include <deal.II/base/mpi.h>

#include <ctime>

namespace shard::base
{
  double
  PhaseTimes::thread_cpu_time()
  {
    timespec t{};
    clock_gettime(CLOCK_THREAD_CPUTIME_ID, &t);
    return t.tv_sec + 1e-9 * t.tv_nsec;
  }

  const std::array<const char *, PhaseTimes::n_phases> &
  PhaseTimes::names()
  {
    static const std::array<const char *, n_phases> n = {{"0 set-up", "1 step size", "2 drift", "3 exchange",
                                                          "4 topology", "5 FE force", "6 particle force", "7 loads",
                                                          "8 accumulate", "9 kick", "10 record"}};
    return n;
  }

  PhaseTimes::Scope::Scope(PhaseTimes &times, const Phase phase)
    : times_(times)
    , phase_(static_cast<unsigned int>(phase))
    , start_(std::chrono::steady_clock::now())
    , cpu_start_(thread_cpu_time())
  {}

  PhaseTimes::Scope::~Scope()
  {
    times_.wall_[phase_] += std::chrono::duration<double>(std::chrono::steady_clock::now() - start_).count();
    times_.cpu_[phase_] += thread_cpu_time() - cpu_start_;
  }

  PhaseTimes::Times
  PhaseTimes::max_wall(MPI_Comm comm) const
  {
    Times result;
    dealii::Utilities::MPI::max(dealii::ArrayView<const double>(wall_.data(), n_phases), comm,
                                dealii::ArrayView<double>(result.data(), n_phases));
    return result;
  }

  void
  PhaseTimes::print_table(std::FILE *out, const Times &max_time, const unsigned int n_threads,
                          const double element_steps, const double particle_steps)
  {
    std::fprintf(out, "\nTime per phase (largest over ranks; %u thread(s) per rank):\n", n_threads);
    double loop = 0;
    for (unsigned int p = 1; p < n_phases; ++p)
      loop += max_time[p];
    for (unsigned int p = 0; p < n_phases; ++p)
      if (max_time[p] > 0)
        std::fprintf(out, "  %-18s %10.3f s  %5.1f %%\n", names()[p], max_time[p], p == 0 ? 0. : 100. * max_time[p] / loop);
    const double fe = max_time[static_cast<unsigned int>(Phase::fe_force)];
    const double pf = max_time[static_cast<unsigned int>(Phase::particle_force)];
    if (fe > 0 && element_steps > 0)
      std::fprintf(out, "  FE force: %.3g element-steps/s (%.3f us per element-step)\n", element_steps / fe,
                   1e6 * fe / element_steps);
    if (pf > 0 && particle_steps > 0)
      std::fprintf(out, "  particle force: %.3g particle-steps/s (%.3f us per particle-step)\n", particle_steps / pf,
                   1e6 * pf / particle_steps);
  }
} // namespace shard::base
