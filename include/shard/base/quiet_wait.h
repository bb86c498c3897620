// SPDX-License-Identifier: LGPL-2.1-or-later
/**
 * @file quiet_wait.h
 * @brief A wait for other ranks that sleeps instead of spinning, for points where some ranks
 *        idle while one works.
 * @ingroup base
 *
 * A rank blocked in an MPI call spins in the library's progress loop. On dedicated cores that
 * costs nothing, but with more ranks than cores (a workstation, the oversubscribed tests) the
 * spinning ranks take CPU from the working ones and book it as their own CPU time, so the set-up
 * of many ranks looks like much more work than it is (doc/performance.md, "MPI scaling"). This wait
 * tests the request every 50 us and sleeps in between: on dedicated cores it adds at most that
 * latency, which is negligible where it is used (rank 0's coarse solve of the correction).
 */
#pragma once

#include <mpi.h>

namespace shard::base
{
  /// Completes @p request, sleeping 50 us between tests. @note Throws on an MPI error.
  void
  wait_quietly(MPI_Request &request);
} // namespace shard::base
