// SPDX-License-Identifier: LGPL-2.1-or-later
/**
 * @file compaction_eos.cc
 * @brief Tabulated compaction EOS (design/materials.md section 4).
 */
#include <shard/materials/compaction_eos.h>

#include <algorithm>

namespace shard::materials
{
  void
  CompactionEos::set_table(const std::vector<double> &strain,
                           const std::vector<double> &pressure,
                           const std::vector<double> &modulus)
  {
    const std::size_t n = strain.size();
    x_.resize(n);
    for (std::size_t i = 0; i < n; ++i)
      x_[i] = -strain[i];
    p_ = pressure;
    k_ = modulus;
    slope_.assign(n, 0.);
    for (std::size_t i = 0; i + 1 < n; ++i)
      slope_[i] = (p_[i + 1] - p_[i]) / (x_[i + 1] - x_[i]);
    if (n > 1)
      slope_[n - 1] = slope_[n - 2];
  }

  unsigned int
  CompactionEos::segment(const double x) const
  {
    // Tables are short (about 10 rows) and most points sit in the first rows.
    const unsigned int n = static_cast<unsigned int>(x_.size());
    unsigned int       k = 0;
    while (k + 2 < n && x_[k + 1] <= x)
      ++k;
    return k;
  }

  double
  CompactionEos::loading_pressure(const double x) const
  {
    const unsigned int k = segment(x);
    return p_[k] + slope_[k] * (x - x_[k]);
  }

  double
  CompactionEos::unloading_modulus(const double x) const
  {
    return modulus_in_segment(segment(x), x);
  }

  double
  CompactionEos::modulus_in_segment(const unsigned int k, const double x) const
  {
    if (x <= x_.front())
      return k_.front();
    if (x >= x_.back())
      return k_.back();
    const double w = (x - x_[k]) / (x_[k + 1] - x_[k]);
    return k_[k] + w * (k_[k + 1] - k_[k]);
  }

  CompactionEos::State
  CompactionEos::evaluate(const double x, const double x_max) const
  {
    State state;
    if (x >= x_max)
      {
        const unsigned int k    = segment(x);
        state.pressure          = p_[k] + slope_[k] * (x - x_[k]);
        state.max_compaction    = x;
        state.unloading_modulus = modulus_in_segment(k, x);
        state.wave_modulus      = std::max(state.unloading_modulus, slope_[k]);
      }
    else
      {
        const unsigned int k    = segment(x_max);
        const double       k_un = modulus_in_segment(k, x_max);
        state.pressure          = p_[k] + slope_[k] * (x_max - x_[k]) - k_un * (x_max - x);
        state.max_compaction    = x_max;
        state.unloading_modulus = k_un;
        state.wave_modulus      = k_un;
      }
    return state;
  }

  double
  CompactionEos::pressure(const double x, const double x_max) const
  {
    if (x >= x_max)
      {
        const unsigned int k = segment(x);
        return p_[k] + slope_[k] * (x - x_[k]);
      }
    const unsigned int k = segment(x_max);
    return p_[k] + slope_[k] * (x_max - x_[k]) - modulus_in_segment(k, x_max) * (x_max - x);
  }

  double
  CompactionEos::compaction_at_pressure(const double target, const double x_max) const
  {
    return x_max - (loading_pressure(x_max) - target) / unloading_modulus(x_max);
  }
} // namespace shard::materials
