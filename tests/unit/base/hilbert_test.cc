// SPDX-License-Identifier: LGPL-2.1-or-later
#include <shard/base/hilbert.h>

#include <gtest/gtest.h>

#include <cstdlib>
#include <vector>

using shard::base::hilbert_index;

// The curve visits every point of a 2^b grid exactly once, and consecutive indices are grid
// neighbours (one coordinate differs by one): the two properties that define a Hilbert curve
// (and that the partition relies on: a range of indices is a connected piece of space).
TEST(Hilbert, VisitsEveryPointOnceWithUnitSteps)
{
  for (unsigned int bits = 1; bits <= 4; ++bits)
    {
      const std::uint32_t            n = 1u << bits;
      std::vector<std::array<int, 3>> at(std::size_t(n) * n * n, {{-1, -1, -1}});
      for (std::uint32_t i = 0; i < n; ++i)
        for (std::uint32_t j = 0; j < n; ++j)
          for (std::uint32_t k = 0; k < n; ++k)
            {
              const std::uint64_t h = hilbert_index({{i, j, k}}, bits);
              ASSERT_LT(h, at.size()) << "bits " << bits;
              ASSERT_EQ(at[h][0], -1) << "index " << h << " visited twice, bits " << bits;
              at[h] = {{int(i), int(j), int(k)}};
            }
      for (std::size_t h = 1; h < at.size(); ++h)
        {
          const int step = std::abs(at[h][0] - at[h - 1][0]) + std::abs(at[h][1] - at[h - 1][1]) +
                           std::abs(at[h][2] - at[h - 1][2]);
          EXPECT_EQ(step, 1) << "indices " << h - 1 << " and " << h << ", bits " << bits;
        }
      // The curve starts at the origin.
      EXPECT_EQ(hilbert_index({{0, 0, 0}}, bits), 0u);
    }
}

// Refinement: the points of one cell of the 2^(b-1) grid are a contiguous block of 8 indices
// of the 2^b grid, in the order of their parent.
TEST(Hilbert, RefinementKeepsTheParentOrder)
{
  const unsigned int bits = 4;
  const std::uint32_t n   = 1u << bits;
  for (std::uint32_t i = 0; i < n; ++i)
    for (std::uint32_t j = 0; j < n; ++j)
      for (std::uint32_t k = 0; k < n; ++k)
        EXPECT_EQ(hilbert_index({{i, j, k}}, bits) / 8, hilbert_index({{i / 2, j / 2, k / 2}}, bits - 1));
}
