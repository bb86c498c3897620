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

namespace shard::base
{
  /**
   * @brief Parses three muparser expressions separated by ';' as a function of x, y, z
   * (and t when @p time_dependent). The constants pi and e are defined.
   *
   * muparser reports syntax errors only when first evaluated, so the function is evaluated
   * once here.
   * @throws std::invalid_argument with the parser's reason for malformed text.
   */
  std::unique_ptr<dealii::FunctionParser<3>>
  parse_vector_function(const std::string &text, bool time_dependent);

  /// True if @p text uses any of the variables x, y, z.
  bool
  depends_on_position(const std::string &text);
} // namespace shard::base
