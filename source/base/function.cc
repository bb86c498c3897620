// SPDX-License-Identifier: LGPL-2.1-or-later
#include <shard/base/function.h>
#include <shard/base/parameters.h>

#include <deal.II/lac/vector.h>

#include <cmath>
#include <iomanip>
#include <iostream>
#include <regex>
#include <sstream>

namespace shard::base
{
  namespace
  {
    /// Silences std::cerr while alive: deal.II's FunctionParser writes muparser's raw error
    /// block (Message, Formula, Token, Position, Errc) there before it throws.
    class SilentCerr
    {
    public:
      SilentCerr()
        : old_(std::cerr.rdbuf(sink_.rdbuf()))
      {}
      ~SilentCerr()
      {
        std::cerr.rdbuf(old_);
      }
      SilentCerr(const SilentCerr &) = delete;
      SilentCerr &
      operator=(const SilentCerr &) = delete;

    private:
      std::ostringstream sink_;
      std::streambuf    *old_;
    };
  } // namespace

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
        const SilentCerr silent;
        f->initialize(time_dependent ? "x,y,z,t" : "x,y,z", parts, {{"pi", M_PI}, {"e", M_E}}, time_dependent);
        dealii::Vector<double> value(3);
        f->vector_value(dealii::Point<3>(0.1, 0.2, 0.3), value);
      }
    catch (const std::exception &e)
      {
        std::string what = e.what();
        const auto  at   = what.find("The parser said:");
        what = at == std::string::npos ? std::string("not a valid muparser expression") : what.substr(at + 17);
        if (const auto trace = what.find("Stacktrace"); trace != std::string::npos)
          what.erase(trace);
        what = std::regex_replace(what, std::regex("\\s+"), " ");
        throw std::invalid_argument(printable(trim(what), 200));
      }
    return f;
  }

  std::string
  non_finite_at(dealii::Function<3> &f, const std::vector<dealii::Point<3>> &points, const double t)
  {
    const double saved = f.get_time();
    f.set_time(t);
    dealii::Vector<double> value(f.n_components);
    std::string            found;
    for (const auto &p : points)
      {
        f.vector_value(p, value);
        for (unsigned int c = 0; c < value.size(); ++c)
          if (!std::isfinite(value[c]))
            {
              std::ostringstream out;
              out << std::setprecision(6) << "component " << c + 1 << " is " << value[c] << " at (" << p[0] << ", "
                  << p[1] << ", " << p[2] << ") m, t = " << t << " s";
              found = out.str();
              break;
            }
        if (!found.empty())
          break;
      }
    f.set_time(saved);
    return found;
  }

  bool
  depends_on_position(const std::string &text)
  {
    return std::regex_search(text, std::regex("\\b[xyz]\\b"));
  }
} // namespace shard::base
