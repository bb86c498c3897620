// SPDX-License-Identifier: LGPL-2.1-or-later
/**
 * @file material.cc
 * @brief Non-virtual helpers and defaults of the batch material interface.
 */
#include <shard/materials/material.h>

#include <algorithm>
#include <cmath>

namespace shard::materials
{
  int
  Material::state_slot(const std::string &name) const
  {
    const std::vector<std::string> names = state_slot_names();
    const auto                     it    = std::find(names.begin(), names.end(), name);
    return it == names.end() ? -1 : static_cast<int>(it - names.begin());
  }

  void
  Material::initialize_state(const unsigned int n, double *state) const
  {
    const std::size_t size = static_cast<std::size_t>(n) * n_state_slots();
    std::fill(state, state + size, 0.);
  }

  void
  Material::set_position_fields(unsigned int, const double *, double *) const
  {}

  void
  Material::write_resolved_parameters(std::ostream &) const
  {}

  double
  Material::elastic_energy_density(const double *s, const double jacobian) const
  {
    const auto   kg = elastic_moduli();
    const double p  = (s[0] + s[1] + s[2]) / 3.;
    double       ss = 0;
    for (unsigned int c = 0; c < 3; ++c)
      ss += (s[c] - p) * (s[c] - p) + 2 * s[c + 3] * s[c + 3];
    const double lj = std::log(jacobian);
    return 0.5 * kg[0] * lj * lj + ss / (4 * kg[1]);
  }
} // namespace shard::materials
