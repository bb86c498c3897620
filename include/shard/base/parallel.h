// SPDX-License-Identifier: LGPL-2.1-or-later
/**
 * @file parallel.h
 * @brief Threads inside an MPI rank: the thread count and loops over a fixed partition into
 *        chunks, so that results do not depend on the number of threads.
 * @ingroup base
 *
 * Every threaded loop of shard runs through for_each_chunk(): the index range is cut into
 * chunks whose bounds depend only on the range and the chunk size, never on the thread count.
 * Each chunk is one task; a chunk writes only what no other chunk of the same loop writes, and
 * a reduction keeps one partial per chunk that the caller adds up serially in chunk order
 * (sum_in_chunk_order()). The same partials in the same order give bitwise the same result for
 * any thread count, including one.
 */
#pragma once

#include <algorithm>
#include <exception>
#include <functional>
#include <vector>

namespace shard::base
{
  /// Largest thread count set_n_threads() accepts.
  constexpr unsigned int max_threads = 1024;

  /**
   * @brief Sets the number of threads of this rank (TBB's global parallelism, which deal.II's
   * own loops follow too). Called once by `shard run --threads N`; the default is 1.
   * @param[in] n from 1 to max_threads.
   */
  void
  set_n_threads(unsigned int n);

  /// The number of threads of this rank set by set_n_threads() (1 when never set).
  unsigned int
  n_threads();

  /// Number of chunks of @p chunk indices that cover [0, @p n).
  inline unsigned int
  n_chunks(const unsigned int n, const unsigned int chunk)
  {
    return (n + chunk - 1) / chunk;
  }

  namespace internal
  {
    /// Runs @p run(c) for c = 0 .. @p n - 1 on the threads of this rank (serially for one).
    void
    run_tasks(unsigned int n, const std::function<void(unsigned int)> &run);
  } // namespace internal

  /**
   * @brief Calls @p body(c, begin, end) for every chunk c of the fixed partition of
   * [0, @p n) into chunks of @p chunk indices, on the threads of this rank.
   *
   * Chunks may run in any order and at the same time, so @p body must only write what belongs
   * to its chunk. An exception thrown by a chunk does not stop the others; after all chunks have
   * run, the exception of the lowest chunk that threw is rethrown. The chunks' work is fixed by
   * their data, so that is the same exception for any thread count.
   */
  template <typename Body>
  void
  for_each_chunk(const unsigned int n, const unsigned int chunk, const Body &body)
  {
    const unsigned int              nc = n_chunks(n, chunk);
    std::vector<std::exception_ptr> error(nc);
    const auto                      run = [&](const unsigned int c) {
      try
        {
          body(c, c * chunk, std::min(n, (c + 1) * chunk));
        }
      catch (...)
        {
          error[c] = std::current_exception();
        }
    };
    if (nc == 1 || n_threads() == 1)
      for (unsigned int c = 0; c < nc; ++c)
        run(c);
    else
      internal::run_tasks(nc, run);
    for (const auto &e : error)
      if (e)
        std::rethrow_exception(e);
  }

  /**
   * @brief Calls @p body(begin, end) on a partition of [0, @p n) into ranges of @p chunk
   * indices, for loops whose iterations are independent and write disjoint results (no
   * reduction, no exceptions expected).
   */
  template <typename Body>
  void
  for_each_range(const unsigned int n, const unsigned int chunk, const Body &body)
  {
    for_each_chunk(n, chunk, [&](unsigned int, const unsigned int begin, const unsigned int end) { body(begin, end); });
  }

  /// Sum of @p partials in index order (the deterministic second half of a chunked reduction).
  inline double
  sum_in_chunk_order(const std::vector<double> &partials)
  {
    double s = 0;
    for (const double p : partials)
      s += p;
    return s;
  }
} // namespace shard::base
