// SPDX-License-Identifier: LGPL-2.1-or-later
// ProgressEstimate (base/progress.h): the remaining wall time at a constant pace and after the
// pace changes.
#include <shard/base/progress.h>

#include <gtest/gtest.h>

namespace
{
  using shard::base::ProgressEstimate;

  TEST(ProgressEstimate, ConstantPaceGivesTheExactRemainingTime)
  {
    // 2 s of wall time per us of simulated time, end at 100 us.
    ProgressEstimate eta(5);
    EXPECT_EQ(eta.remaining(100e-6), 0.);
    eta.add(20., 10e-6);
    EXPECT_NEAR(eta.remaining(100e-6), 180., 1e-9); // one sample: the pace since the start
    for (int k = 2; k <= 9; ++k)
      eta.add(20. * k, 10e-6 * k);
    EXPECT_NEAR(eta.remaining(100e-6), 20., 1e-9);
    EXPECT_EQ(eta.remaining(50e-6), 0.); // past the end
  }

  TEST(ProgressEstimate, FollowsTheNewPaceAfterTheWindow)
  {
    // 1 s per us up to 50 us, then 4 s per us: the mean since the start would say 2.5 s per us
    // at 60 us; after a window of samples at the new pace the estimate is 4 s per us.
    ProgressEstimate eta(4);
    double           wall = 0.;
    for (int k = 1; k <= 5; ++k)
      eta.add(wall += 10., 10e-6 * k);
    EXPECT_NEAR(eta.remaining(100e-6), 50., 1e-9);
    for (int k = 6; k <= 9; ++k)
      eta.add(wall += 40., 10e-6 * k);
    EXPECT_NEAR(eta.remaining(100e-6), 10e-6 * 4e6, 1e-6); // 10 us left at 4 s per us
  }
} // namespace
