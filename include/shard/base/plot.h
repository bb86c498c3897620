// SPDX-License-Identifier: LGPL-2.1-or-later
/**
 * @file plot.h
 * @brief Runs a plotting script of contrib/utilities with /usr/bin/python3 (matplotlib).
 * @ingroup base
 */
#pragma once

#include <string>
#include <vector>

namespace shard::base
{
  /**
   * @brief Runs `/usr/bin/python3 <source tree>/contrib/utilities/<script> <arguments...>`.
   * Plots are a convenience: nothing here stops a run.
   * @return empty on success, otherwise a one-paragraph warning (no script, no python, or the
   *         script's exit code, the command and its output)
   */
  std::string
  run_plot_script(const std::string &script, const std::vector<std::string> &arguments);
} // namespace shard::base
