// SPDX-License-Identifier: LGPL-2.1-or-later
/**
 * @file function.h
 * @brief Vector-valued muparser functions of x, y, z (and t) from .prm text.
 * @ingroup base
 */
#pragma once

#include <deal.II/base/function_parser.h>

#include <memory>
#include <string>
#include <vector>

namespace shard::base
{
  /**
   * @brief Parses three muparser expressions separated by ';' as a function of x, y, z
   * (and t when @p time_dependent). The constants pi and e are defined.
   *
   * muparser reports syntax errors only when first evaluated, so the function is evaluated
   * once here (with muparser's own report to std::cerr silenced).
   * @throws std::invalid_argument with the parser's reason for malformed text, in one line.
   */
  std::unique_ptr<dealii::FunctionParser<3>>
  parse_vector_function(const std::string &text, bool time_dependent);

  /**
   * @brief Evaluates @p f at every one of @p points at time @p t; returns where a component is
   * first not finite ("component 1 is inf at (x, y, z) m, t = 0 s"), or "" when all are finite.
   * The function's time is restored afterwards.
   */
  std::string
  non_finite_at(dealii::Function<3> &f, const std::vector<dealii::Point<3>> &points, double t);

  /// True if @p text uses any of the variables x, y, z.
  bool
  depends_on_position(const std::string &text);
} // namespace shard::base
