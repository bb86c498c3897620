// SPDX-License-Identifier: LGPL-2.1-or-later
/**
 * @file traffic.h
 * @brief Bytes a rank sends at the named exchange points of the step.
 * @ingroup base
 */
#pragma once

#include <mpi.h>

#include <array>
#include <string>

namespace shard::base
{
  /**
   * @brief The payload bytes this rank sends to other ranks at each exchange point of the
   * step (doc/manual/time_loop.md), summed over the steps of the run.
   *
   * Counted is what the algorithm sends, not what MPI adds: a ghost update sends 8 bytes per
   * owned entry another rank imports, a compress 8 bytes per ghost entry, a gather to all ranks
   * its payload once per other rank (what a ring or tree all-gather moves out of each rank in
   * total). Scalar reductions (the step size, the failure and event flags) are left out: their
   * size does not depend on the model. Conversion events are not step traffic and are not
   * counted. summary.json reports the mean per step (`bytes_sent_per_step_by_rank`).
   */
  class Traffic
  {
  public:
    /// The exchange points that move model data.
    enum Exchange : unsigned int
    {
      /// Phase 3: ghost values of d and v (twice on filter steps).
      ghost_values = 0,
      /// Phase 3: positions and velocities of the contact halo nodes (at a candidate rebuild:
      /// the halo's records and the ranks' bounding boxes).
      contact_nodes = 1,
      /// Phase 4c: failure values of the particles and the lists of broken bonds and freed particles.
      bonds = 2,
      /// Phase 8 (and 4c): ghost force sums to their owners.
      ghost_sums = 3,
      /// Phase 8: contact forces on halo nodes to their owners.
      contact_forces = 4,
      n_exchanges = 5
    };

    /// The names in summary.json, led by the phase number.
    static const std::array<std::string, n_exchanges> &
    names()
    {
      static const std::array<std::string, n_exchanges> n{
        {"3 ghost values", "3 contact nodes", "4c bonds", "8 ghost sums", "8 contact forces"}};
      return n;
    }

    /// Adds @p bytes sent at @p where in the current step.
    void
    add(const Exchange where, const double bytes)
    {
      bytes_[where] += bytes;
    }

    /// Counts one step (the mean per step divides by the steps counted).
    void
    count_step()
    {
      ++steps_;
    }

    /// Steps counted.
    double
    steps() const
    {
      return steps_;
    }

    /// The mean bytes per step sent at @p where (0 before the first step).
    double
    per_step(const Exchange where) const
    {
      return steps_ > 0 ? bytes_[where] / steps_ : 0.;
    }

    /// What a gather to all ranks of @p bytes from this rank sends: @p bytes to each other rank.
    static double
    to_all_others(const double bytes, const MPI_Comm comm)
    {
      int n = 1;
      MPI_Comm_size(comm, &n);
      return bytes * (n - 1);
    }

  private:
    std::array<double, n_exchanges> bytes_{};
    double                          steps_ = 0;
  };
} // namespace shard::base
