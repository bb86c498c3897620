// SPDX-License-Identifier: LGPL-2.1-or-later
#include <shard/base/function.h>
#include <shard/base/parameters.h>

#include <deal.II/lac/vector.h>

#include <cmath>
#include <regex>

namespace shard::base
{
  std::unique_ptr<dealii::FunctionParser<3>>
  parse_vector_function(const std::string &text, const bool time_dependent)
  {
    const auto parts = split(text, ';');
    if (parts.size() != 3)
      throw std::invalid_argument("expected three expressions separated by ';', found " +
                                  std::to_string(parts.size()));
    auto f = std::make_unique<dealii::FunctionParser<3>>(3);
    try
      {
        f->initialize(time_dependent ? "x,y,z,t" : "x,y,z", parts, {{"pi", M_PI}, {"e", M_E}}, time_dependent);
        dealii::Vector<double> value(3);
        f->vector_value(dealii::Point<3>(0.1, 0.2, 0.3), value);
      }
    catch (const std::exception &e)
      {
        std::string what = e.what();
        const auto  at   = what.find("The parser said:");
        what = at == std::string::npos ? std::string("not a valid muparser expression") : what.substr(at + 17);
        what = std::regex_replace(what, std::regex("\\s*\\n\\s*"), " ");
        throw std::invalid_argument(trim(what));
      }
    return f;
  }

  bool
  depends_on_position(const std::string &text)
  {
    return std::regex_search(text, std::regex("\\b[xyz]\\b"));
  }
} // namespace shard::base
