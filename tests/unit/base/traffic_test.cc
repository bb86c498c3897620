// SPDX-License-Identifier: LGPL-2.1-or-later
// Traffic (base/traffic.h): bytes per exchange point, the mean per counted step.
#include <shard/base/traffic.h>

#include <gtest/gtest.h>

#include <mpi.h>

using shard::base::Traffic;

TEST(Traffic, MeanPerStepPerExchange)
{
  Traffic t;
  EXPECT_EQ(t.per_step(Traffic::ghost_values), 0.); // no step yet: 0, not NaN
  t.count_step();
  t.add(Traffic::ghost_values, 96);
  t.add(Traffic::contact_nodes, 480);
  t.count_step();
  t.add(Traffic::ghost_values, 192); // a filter step: twice
  t.count_step();
  EXPECT_EQ(t.steps(), 3.);
  EXPECT_EQ(t.per_step(Traffic::ghost_values), 96.);
  EXPECT_EQ(t.per_step(Traffic::contact_nodes), 160.);
  EXPECT_EQ(t.per_step(Traffic::bonds), 0.);
  EXPECT_EQ(Traffic::names()[Traffic::ghost_sums], "8 ghost sums");
  EXPECT_EQ(Traffic::names()[Traffic::contact_forces], "8 contact forces");
}

TEST(Traffic, GatherToAllOthers)
{
  // One process in the unit tests: a gather sends nothing.
  EXPECT_EQ(Traffic::to_all_others(4800., MPI_COMM_SELF), 0.);
}
