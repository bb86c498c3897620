// SPDX-License-Identifier: LGPL-2.1-or-later
// PhaseTimes (base/phase_timer.h): a scope adds its wall and CPU time to its phase only.
#include <shard/base/phase_timer.h>

#include <gtest/gtest.h>

#include <chrono>
#include <cmath>
#include <string>
#include <thread>

using shard::base::Phase;
using shard::base::PhaseTimes;

TEST(PhaseTimes, NamesFollowThePhaseNumbers)
{
  EXPECT_EQ(PhaseTimes::names().size(), 11u);
  EXPECT_EQ(std::string(PhaseTimes::names()[static_cast<unsigned int>(Phase::topology)]), "4 topology");
  EXPECT_EQ(std::string(PhaseTimes::names()[static_cast<unsigned int>(Phase::record)]), "10 record");
}

TEST(PhaseTimes, ScopeAddsToItsPhase)
{
  PhaseTimes times;
  {
    const auto timer = times.scope(Phase::kick);
    std::this_thread::sleep_for(std::chrono::milliseconds(20)); // wall time, little CPU
  }
  volatile double x = 0;
  {
    const auto timer = times.scope(Phase::fe_force);
    const auto start = std::chrono::steady_clock::now();
    while (std::chrono::steady_clock::now() - start < std::chrono::milliseconds(20))
      x = x + std::sqrt(x + 1.); // CPU time
  }
  const unsigned int kick = static_cast<unsigned int>(Phase::kick), fe = static_cast<unsigned int>(Phase::fe_force);
  EXPECT_GE(times.wall()[kick], 0.02);
  EXPECT_LT(times.cpu()[kick], times.wall()[kick]);
  EXPECT_GE(times.wall()[fe], 0.02);
  EXPECT_GT(times.cpu()[fe], 0.);
  for (unsigned int p = 0; p < PhaseTimes::n_phases; ++p)
    if (p != kick && p != fe)
      {
        EXPECT_EQ(times.wall()[p], 0.) << p;
      }
  times.add(Phase::setup, 1.5, 0.5);
  EXPECT_EQ(times.wall()[0], 1.5);
  EXPECT_EQ(times.cpu()[0], 0.5);
  times.reset_cpu();
  EXPECT_EQ(times.cpu()[fe], 0.);
  EXPECT_EQ(times.cpu()[0], 0.5); // the set-up's CPU time is kept for summary.json
  EXPECT_EQ(times.max_wall(MPI_COMM_SELF), times.wall());
}
