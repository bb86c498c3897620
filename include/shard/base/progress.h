// SPDX-License-Identifier: LGPL-2.1-or-later
/**
 * @file progress.h
 * @brief Estimated time to the end of a run from the recent pace (wall time per simulated time).
 * @ingroup base
 */
#pragma once

#include <cstddef>
#include <deque>
#include <utility>

namespace shard::base
{
  /**
   * @brief ETA of a time loop from its recent pace.
   *
   * The pace of an explicit run is not constant: conversion adds particles, the stable step
   * shrinks as the material crushes. The mean pace since the start then underestimates what is
   * left (a Hanchak run showed 16 s at 11 % of 99 s). This keeps the last @p window samples of
   * (wall time, simulated time) and extrapolates the pace between the oldest kept sample and
   * the newest one: at a constant pace that is the exact remaining time, after a change of pace
   * it follows the new one once @p window samples have passed.
   */
  class ProgressEstimate
  {
  public:
    /// Keeps the last @p window samples (at least 2).
    explicit ProgressEstimate(const std::size_t window = 10)
      : window_(window < 2 ? 2 : window)
    {}

    /// Adds the sample (wall time since the start, simulated time), both in s.
    void
    add(const double wall, const double time)
    {
      samples_.emplace_back(wall, time);
      while (samples_.size() > window_)
        samples_.pop_front();
    }

    /**
     * Estimated wall time (s) to reach the simulated time @p end: the remaining simulated time
     * times the pace between the oldest and the newest sample kept, or the pace since the start
     * (wall 0 at time @p start) while only one sample is kept. 0 before any progress.
     */
    double
    remaining(const double end, const double start = 0.) const
    {
      if (samples_.empty())
        return 0.;
      const auto &[w1, t1] = samples_.back();
      auto [w0, t0]        = samples_.size() > 1 ? samples_.front() : std::pair<double, double>(0., start);
      if (!(t1 > t0))
        return 0.;
      return (w1 - w0) / (t1 - t0) * (end > t1 ? end - t1 : 0.);
    }

  private:
    std::size_t                              window_;
    std::deque<std::pair<double, double>> samples_;
  };
} // namespace shard::base
