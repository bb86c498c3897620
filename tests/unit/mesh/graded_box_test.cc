// SPDX-License-Identifier: LGPL-2.1-or-later
// Cell sizes of the graded box (mesh::graded_cell_sizes): they fill the edge exactly, the fine
// core has uniform cells no larger than h, the cells outside grow by at most the ratio per cell
// and never exceed the unscaled geometric size h r^k.
#include <shard/mesh/discretization.h>

#include <gtest/gtest.h>

#include <numeric>

namespace
{
  void
  check(const double lower, const double upper, const double fl, const double fu, const double h, const double r)
  {
    const auto sizes = shard::mesh::graded_cell_sizes(lower, upper, fl, fu, h, r);
    ASSERT_FALSE(sizes.empty());
    EXPECT_NEAR(std::accumulate(sizes.begin(), sizes.end(), 0.), upper - lower, 1e-12 * (upper - lower));
    double x = lower;
    std::vector<double> core;
    for (const double s : sizes)
      {
        EXPECT_GT(s, 0.);
        if (x >= fl - 1e-12 && x + s <= fu + 1e-12)
          core.push_back(s);
        x += s;
      }
    ASSERT_FALSE(core.empty());
    for (const double s : core)
      {
        EXPECT_LE(s, h * (1 + 1e-12));
        EXPECT_NEAR(s, core.front(), 1e-12 * h);
      }
    EXPECT_NEAR(std::accumulate(core.begin(), core.end(), 0.), fu - fl, 1e-9 * h);
    for (std::size_t i = 1; i < sizes.size(); ++i)
      {
        const double q = sizes[i] / sizes[i - 1];
        EXPECT_LE(q, r * (1 + 1e-9));
        EXPECT_GE(q, 1 / r * (1 - 1e-9));
      }
    EXPECT_LE(*std::max_element(sizes.begin(), sizes.end()), h * std::pow(r, sizes.size()));
  }
} // namespace

TEST(GradedBox, FillsTheEdgeWithAUniformCoreAndBoundedGrowth)
{
  check(-0.305, 0.305, -0.08, 0.08, 0.006, 1.2); // the Hanchak slab's plan
  check(0., 1., 0.3, 0.5, 0.01, 1.05);            // off-centre core
  check(0., 1., 0., 0.5, 0.01, 1.5);              // core at one end: one growing side
}

TEST(GradedBox, RatioOneIsUniform)
{
  const auto sizes = shard::mesh::graded_cell_sizes(0., 1., 0.2, 0.4, 0.1, 1.);
  ASSERT_EQ(sizes.size(), 10u);
  for (const double s : sizes)
    EXPECT_NEAR(s, 0.1, 1e-12);
}

TEST(GradedBox, CoreCoveringTheBoxIsUniform)
{
  const auto sizes = shard::mesh::graded_cell_sizes(0., 0.178, 0., 0.178, 0.006, 1.2);
  ASSERT_EQ(sizes.size(), 30u);
  for (const double s : sizes)
    EXPECT_NEAR(s, 0.178 / 30, 1e-12);
}
