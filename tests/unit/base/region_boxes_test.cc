// SPDX-License-Identifier: LGPL-2.1-or-later
// base/region_boxes.h: the boxes cover every point tightly, there are at most 512, and
// for_each_near() visits exactly the points within the reach of another rank's boxes (against a
// brute-force count in the max norm).
#include <shard/base/region_boxes.h>

#include <gtest/gtest.h>

#include <cmath>
#include <random>
#include <vector>

namespace
{
  using shard::base::Point;
  using shard::base::RegionBoxes;

  /// Two clusters far apart: a rank whose cells are at both ends of a block.
  std::vector<Point>
  two_clusters(const unsigned int n)
  {
    std::mt19937                           gen(7);
    std::uniform_real_distribution<double> u(0., 1.);
    std::vector<Point>                     x;
    for (unsigned int i = 0; i < n; ++i)
      {
        const double shift = i % 2 ? 100. : 0.;
        x.push_back(Point{{shift + u(gen), u(gen), u(gen)}});
      }
    return x;
  }

  TEST(RegionBoxes, BoxesHoldEveryPointAndAreFew)
  {
    const auto        x = two_clusters(2000);
    const RegionBoxes region(x, 0.5);
    ASSERT_EQ(region.boxes.size() % 6, 0u);
    EXPECT_LE(region.boxes.size() / 6, 512u);
    // Two clusters 100 m apart in a grid of edge 100/8: the gap stays empty, so the boxes'
    // volume is that of the clusters (2 x 1 m^3 at most), not of the 100 m span.
    double volume = 0;
    for (std::size_t b = 0; b < region.boxes.size(); b += 6)
      volume += (region.boxes[b + 3] - region.boxes[b]) * (region.boxes[b + 4] - region.boxes[b + 1]) *
                (region.boxes[b + 5] - region.boxes[b + 2]);
    EXPECT_LE(volume, 2.0);
    for (const auto &p : x)
      {
        bool inside = false;
        for (std::size_t b = 0; b < region.boxes.size() && !inside; b += 6)
          inside = RegionBoxes::max_norm_gap(p.data(), p.data(), &region.boxes[b], &region.boxes[b + 3]) <= 0;
        EXPECT_TRUE(inside);
      }
  }

  TEST(RegionBoxes, NearPointsAreThoseWithinTheReach)
  {
    const auto                x = two_clusters(3000);
    const RegionBoxes         region(x, 0.4);
    const std::vector<double> other{100.9, 0.2, 0.2, 102., 0.6, 0.6, -3., -3., -3., -0.05, 0.1, 0.1};
    const double              reach = 0.2;
    std::vector<int>          seen(x.size(), 0);
    region.for_each_near(other, reach, [&](const std::size_t p) { ++seen[p]; });
    unsigned int expected = 0, visited = 0;
    for (std::size_t p = 0; p < x.size(); ++p)
      {
        bool near = false;
        for (std::size_t o = 0; o < other.size(); o += 6)
          near |= RegionBoxes::max_norm_gap(x[p].data(), x[p].data(), &other[o], &other[o + 3]) <= reach;
        expected += near;
        visited += seen[p];
        EXPECT_EQ(seen[p], near ? 1 : 0) << "point " << p;
      }
    EXPECT_GT(expected, 10u); // both boxes catch some points
    EXPECT_EQ(visited, expected);
  }

  TEST(RegionBoxes, NoPointsNoBoxes)
  {
    const std::vector<Point> none;
    const RegionBoxes        region(none, 1.);
    EXPECT_TRUE(region.boxes.empty());
    region.for_each_near({0., 0., 0., 1., 1., 1.}, 1., [](std::size_t) { FAIL(); });
  }
} // namespace
