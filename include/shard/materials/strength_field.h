// SPDX-License-Identifier: LGPL-2.1-or-later
/**
 * @file strength_field.h
 * @brief A random Weibull strength field of mean 1 on a fixed grid of the reference
 *        configuration: the flaws that decide where a uniformly stretched body breaks first.
 * @ingroup materials
 *
 * Theory, parameters and the measurements that motivated it: doc/materials/kcc.md,
 * "Strength field" (decision 13).
 */
#pragma once

#include <cmath>
#include <cstdint>

namespace shard::materials
{
  /**
   * @brief Strength factor s(X) of a point at reference position X: Weibull distributed with
   * modulus m and mean 1, constant on the cells of a cubic grid of size l that is fixed in
   * space, independent from cell to cell.
   *
   * The value of a cell is a function of its integer indices and the seed only (a 64-bit
   * hash), so it is the same on every rank, for every mesh and particle spacing that puts a
   * point in that cell, and after a restart. A finer discretization therefore samples the same
   * field: the flaws are a property of the material, not of the lattice. The grid is shifted by
   * 1/pi of a cell so that the nodes of a regular mesh with the origin on a node do not lie on
   * cell boundaries.
   *
   * With u uniform in (0, 1) the factor is the Weibull quantile over its mean,
   * s = (-ln(1 - u))^(1/m) / Gamma(1 + 1/m); its coefficient of variation is
   * sqrt(Gamma(1 + 2/m) / Gamma(1 + 1/m)^2 - 1) (m = 8: 0.149; m = 12: 0.102).
   */
  class StrengthField
  {
  public:
    /// An inactive field (factor 1 everywhere).
    StrengthField() = default;

    /**
     * @param modulus Weibull modulus m (0: inactive)
     * @param cell_size grid size l (m), > 0 when m > 0
     * @param seed selects the realization
     */
    StrengthField(const double modulus, const double cell_size, const std::uint64_t seed)
      : modulus_(modulus)
      , cell_size_(cell_size)
      , seed_(seed)
      , mean_(modulus > 0 ? std::tgamma(1. + 1. / modulus) : 1.)
    {}

    /// Whether the field varies (m > 0).
    bool
    active() const
    {
      return modulus_ > 0 && cell_size_ > 0;
    }

    /// The factor at reference position @p x (3 coordinates, m); 1 if inactive.
    double
    factor(const double *x) const
    {
      if (!active())
        return 1.;
      std::uint64_t h = mix(seed_ + 0x9e3779b97f4a7c15ULL);
      for (unsigned int c = 0; c < 3; ++c)
        {
          const double        i = std::floor(x[c] / cell_size_ + grid_shift);
          const std::int64_t  k = static_cast<std::int64_t>(i);
          h = mix(h ^ (static_cast<std::uint64_t>(k) + 0x9e3779b97f4a7c15ULL * (c + 1)));
        }
      return quantile(uniform(h), modulus_) / mean_;
    }

    /// The Weibull quantile (-ln(1 - u))^(1/m) of @p u in (0, 1) (not divided by the mean).
    static double
    quantile(const double u, const double modulus)
    {
      return std::pow(-std::log1p(-u), 1. / modulus);
    }

    /// The coefficient of variation of the factor for modulus @p m.
    static double
    coefficient_of_variation(const double m)
    {
      const double g1 = std::tgamma(1. + 1. / m), g2 = std::tgamma(1. + 2. / m);
      return std::sqrt(g2 / (g1 * g1) - 1.);
    }

    /// A number in (0, 1) from the 53 high bits of @p h (never 0 or 1).
    static double
    uniform(const std::uint64_t h)
    {
      return (static_cast<double>(h >> 11) + 0.5) * (1. / 9007199254740992.);
    }

    /// SplitMix64 finalizer: a bijective 64-bit mix with full avalanche.
    static std::uint64_t
    mix(std::uint64_t z)
    {
      z += 0x9e3779b97f4a7c15ULL;
      z = (z ^ (z >> 30)) * 0xbf58476d1ce4e5b9ULL;
      z = (z ^ (z >> 27)) * 0x94d049bb133111ebULL;
      return z ^ (z >> 31);
    }

    /// Shift of the grid, a fraction of a cell (1/pi).
    static constexpr double grid_shift = 0.3183098861837907;

  private:
    double        modulus_   = 0.;
    double        cell_size_ = 0.;
    std::uint64_t seed_      = 0;
    double        mean_      = 1.;
  };
} // namespace shard::materials
