// SPDX-License-Identifier: LGPL-2.1-or-later
#include <shard/base/parallel.h>
#include <shard/base/quiet_wait.h>

#include <deal.II/base/multithread_info.h>

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/partitioner.h>

#include <chrono>
#include <cstdlib>
#include <stdexcept>
#include <string>
#include <thread>

namespace shard::base
{
  void
  set_n_threads(const unsigned int n)
  {
    if (n < 1 || n > max_threads)
      throw std::invalid_argument("thread count " + std::to_string(n) + " outside 1 to " +
                                  std::to_string(max_threads));
    // deal.II keeps the one TBB limit of the process and caps it by DEAL_II_NUM_THREADS
    // (contrib/setup.sh exports 1); an explicit count replaces both.
    setenv("DEAL_II_NUM_THREADS", std::to_string(n).c_str(), 1);
    dealii::MultithreadInfo::set_thread_limit(n);
  }

  unsigned int
  n_threads()
  {
    return dealii::MultithreadInfo::n_threads();
  }

  namespace internal
  {
    void
    run_tasks(const unsigned int n, const std::function<void(unsigned int)> &run)
    {
      // One task per chunk: which thread runs a chunk does not change what it computes.
      tbb::parallel_for(
        tbb::blocked_range<unsigned int>(0, n, 1),
        [&](const tbb::blocked_range<unsigned int> &r) {
          for (unsigned int c = r.begin(); c < r.end(); ++c)
            run(c);
        },
        tbb::simple_partitioner());
    }
  } // namespace internal

  void
  wait_quietly(MPI_Request &request)
  {
    for (int done = 0;;)
      {
        if (MPI_Test(&request, &done, MPI_STATUS_IGNORE) != MPI_SUCCESS)
          throw std::runtime_error("MPI_Test failed while waiting for the other ranks");
        if (done)
          return;
        std::this_thread::sleep_for(std::chrono::microseconds(50));
      }
  }
} // namespace shard::base
