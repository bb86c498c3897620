// SPDX-License-Identifier: LGPL-2.1-or-later
// The chunked loops of base/parallel.h: fixed partition, deterministic reductions and
// exceptions, for one and several threads.
#include <shard/base/parallel.h>

#include <gtest/gtest.h>

#include <atomic>
#include <chrono>
#include <cmath>
#include <cstring>
#include <stdexcept>
#include <string>
#include <thread>
#include <vector>

namespace
{
  using namespace shard;

  /// Restores one thread when a test ends.
  struct ThreadCount
  {
    explicit ThreadCount(const unsigned int n)
    {
      base::set_n_threads(n);
    }
    ~ThreadCount()
    {
      base::set_n_threads(1);
    }
  };

  /// Values whose sum depends on the order of the additions.
  std::vector<double>
  awkward_values(const unsigned int n)
  {
    std::vector<double> x(n);
    for (unsigned int i = 0; i < n; ++i)
      x[i] = std::sin(1.3 * i) * std::pow(10., static_cast<int>(i % 17) - 8);
    return x;
  }

  /// Per-chunk partials, then the sum in chunk order.
  double
  chunked_sum(const std::vector<double> &x, const unsigned int chunk)
  {
    std::vector<double> partial(base::n_chunks(x.size(), chunk));
    base::for_each_chunk(x.size(), chunk, [&](const unsigned int c, const unsigned int begin, const unsigned int end) {
      double s = 0;
      for (unsigned int i = begin; i < end; ++i)
        s += x[i];
      partial[c] = s;
    });
    return base::sum_in_chunk_order(partial);
  }
} // namespace

TEST(Parallel, ThreadCountIsSetAndChecked)
{
  EXPECT_EQ(base::n_threads(), 1u);
  {
    ThreadCount three(3);
    EXPECT_EQ(base::n_threads(), 3u);
  }
  EXPECT_EQ(base::n_threads(), 1u);
  EXPECT_THROW(base::set_n_threads(0), std::invalid_argument);
  EXPECT_THROW(base::set_n_threads(base::max_threads + 1), std::invalid_argument);
}

TEST(Parallel, ChunksAreFixedAndCoverTheRangeOnce)
{
  const unsigned int n = 1000, chunk = 64;
  EXPECT_EQ(base::n_chunks(n, chunk), 16u);
  EXPECT_EQ(base::n_chunks(0, chunk), 0u);
  for (const unsigned int threads : {1u, 3u})
    {
      ThreadCount                    count(threads);
      std::vector<std::atomic<int>>  visits(n);
      std::vector<unsigned int>      first(16, 0), last(16, 0);
      base::for_each_chunk(n, chunk, [&](const unsigned int c, const unsigned int begin, const unsigned int end) {
        first[c] = begin;
        last[c]  = end;
        for (unsigned int i = begin; i < end; ++i)
          ++visits[i];
      });
      for (unsigned int i = 0; i < n; ++i)
        EXPECT_EQ(visits[i].load(), 1) << "index " << i << ", " << threads << " threads";
      for (unsigned int c = 0; c < 16; ++c)
        {
          EXPECT_EQ(first[c], c * chunk);
          EXPECT_EQ(last[c], std::min(n, (c + 1) * chunk));
        }
    }
}

TEST(Parallel, SeveralThreadsRun)
{
  // Chunks that wait for each other finish only if two threads run them at the same time.
  ThreadCount       count(2);
  std::atomic<int>  started{0};
  std::atomic<bool> overlapped{false};
  base::for_each_chunk(2, 1, [&](unsigned int, unsigned int, unsigned int) {
    ++started;
    for (int k = 0; k < 2000 && started.load() < 2; ++k)
      std::this_thread::sleep_for(std::chrono::milliseconds(1));
    if (started.load() == 2)
      overlapped = true;
  });
  EXPECT_TRUE(overlapped.load());
}

TEST(Parallel, ChunkedSumIsTheSameForAnyThreadCount)
{
  const auto x = awkward_values(100000);
  // The chunked sum does not depend on the threads, to the bit; it is close to the serial sum.
  const double one = chunked_sum(x, 1000);
  for (const unsigned int threads : {2u, 3u, 4u})
    {
      ThreadCount  count(threads);
      const double s = chunked_sum(x, 1000);
      EXPECT_EQ(std::memcmp(&s, &one, sizeof(double)), 0) << threads << " threads: " << s << " != " << one;
    }
  double serial = 0;
  for (const double v : x)
    serial += v;
  EXPECT_NEAR(one, serial, 1e-12 * std::abs(serial) + 1e-20);
}

TEST(Parallel, TheLowestFailingChunkWins)
{
  for (const unsigned int threads : {1u, 3u})
    {
      ThreadCount               count(threads);
      std::vector<unsigned int> ran(40, 0);
      try
        {
          base::for_each_chunk(40 * 8, 8, [&](const unsigned int c, unsigned int, unsigned int) {
            ran[c] = 1;
            if (c == 31 || c == 7 || c == 19)
              throw std::runtime_error("chunk " + std::to_string(c));
          });
          FAIL() << "no exception";
        }
      catch (const std::runtime_error &e)
        {
          EXPECT_STREQ(e.what(), "chunk 7") << threads << " threads";
        }
      // Every chunk ran: what the others computed does not depend on which failed first.
      for (unsigned int c = 0; c < 40; ++c)
        EXPECT_EQ(ran[c], 1u) << "chunk " << c;
    }
}
