// SPDX-License-Identifier: LGPL-2.1-or-later
/**
 * @file instability.h
 * @brief The exception of a run that went unstable (doc/manual/time_loop.md, rule 3 of the house).
 * @ingroup base
 */
#pragma once

#include <stdexcept>

namespace shard
{
  /**
   * @brief A run that went unstable (inverted element or particle, non-finite stress or energy,
   * energy error above its limit, collapsed step): the message names the step, the place and
   * the quantity. Simulation catches it, keeps the last good output and exits with code 3.
   */
  class Instability : public std::runtime_error
  {
  public:
    using std::runtime_error::runtime_error;
  };
} // namespace shard
