// SPDX-License-Identifier: LGPL-2.1-or-later
// Binned candidate search for RK stencils: see include/shard/particles/neighbor_build.h.
#include <shard/particles/neighbor_build.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <stdexcept>

namespace shard::particles
{
  namespace
  {
    /// Whether the support of a particle at distance r = X - X_I with radii a contains X.
    bool
    inside_support(const Point3 &r, const Point3 &a, const Support support)
    {
      if (support == Support::box)
        return std::abs(r[0]) < a[0] && std::abs(r[1]) < a[1] && std::abs(r[2]) < a[2];
      const double z0 = r[0] / a[0], z1 = r[1] / a[1], z2 = r[2] / a[2];
      return z0 * z0 + z1 * z1 + z2 * z2 < 1.0;
    }
  } // namespace


  CsrPattern
  find_support_neighbors(const std::vector<Point3> &eval_points,
                         const std::vector<Point3> &particle_positions,
                         const std::vector<Point3> &support_radii,
                         const Support              support)
  {
    const std::size_t n = particle_positions.size();
    if (support_radii.size() != n)
      throw std::invalid_argument("find_support_neighbors: support_radii must have one entry per particle");
    if (n > std::numeric_limits<unsigned int>::max() || eval_points.size() >= std::numeric_limits<unsigned int>::max())
      throw std::invalid_argument("find_support_neighbors: too many points for unsigned int indices");

    CsrPattern result;
    result.row_offsets.assign(1, 0u);
    result.row_offsets.reserve(eval_points.size() + 1);
    if (n == 0)
      {
        result.row_offsets.resize(eval_points.size() + 1, 0u);
        return result;
      }

    // ---- bin geometry: edge b > largest radius, at most about 2 N bins
    double a_max = 0.0;
    Point3 lo    = particle_positions[0];
    Point3 hi    = particle_positions[0];
    for (std::size_t i = 0; i < n; ++i)
      for (unsigned int k = 0; k < 3; ++k)
        {
          const double a = support_radii[i][k];
          if (!(a > 0.0) || !std::isfinite(a))
            throw std::invalid_argument("find_support_neighbors: support radii must be positive and finite");
          if (!std::isfinite(particle_positions[i][k]))
            throw std::invalid_argument("find_support_neighbors: particle positions must be finite");
          a_max = std::max(a_max, a);
          lo[k] = std::min(lo[k], particle_positions[i][k]);
          hi[k] = std::max(hi[k], particle_positions[i][k]);
        }
    // The relative margin keeps "|X_k - X_kI| < a  =>  bin indices differ by at most 1" true under
    // the rounding of (x - lo) / b.
    double       b        = a_max * (1.0 + 1e-6);
    const double max_bins = std::max(64.0, 2.0 * static_cast<double>(n));
    std::int64_t nb[3];
    for (;;)
      {
        double total = 1.0;
        for (unsigned int k = 0; k < 3; ++k)
          total *= std::floor((hi[k] - lo[k]) / b) + 1.0;
        if (total <= max_bins)
          break;
        b *= std::max(1.01, std::cbrt(total / max_bins));
      }
    for (unsigned int k = 0; k < 3; ++k)
      nb[k] = static_cast<std::int64_t>(std::floor((hi[k] - lo[k]) / b)) + 1;
    const std::size_t n_bins = static_cast<std::size_t>(nb[0] * nb[1] * nb[2]);

    const auto bin_coordinate = [&](const double x, const unsigned int k) {
      return std::floor((x - lo[k]) / b);
    };

    // ---- counting sort of the particles by bin (ascending particle index within a bin)
    std::vector<std::size_t>  bin_of(n);
    std::vector<unsigned int> bin_offsets(n_bins + 1, 0u);
    for (std::size_t i = 0; i < n; ++i)
      {
        std::int64_t c[3];
        for (unsigned int k = 0; k < 3; ++k)
          c[k] = std::clamp<std::int64_t>(static_cast<std::int64_t>(bin_coordinate(particle_positions[i][k], k)),
                                          0,
                                          nb[k] - 1);
        bin_of[i] = static_cast<std::size_t>((c[2] * nb[1] + c[1]) * nb[0] + c[0]);
        ++bin_offsets[bin_of[i] + 1];
      }
    for (std::size_t c = 0; c < n_bins; ++c)
      bin_offsets[c + 1] += bin_offsets[c];
    std::vector<unsigned int> bin_particles(n);
    {
      std::vector<unsigned int> next(bin_offsets.begin(), bin_offsets.end() - 1);
      for (std::size_t i = 0; i < n; ++i)
        bin_particles[next[bin_of[i]]++] = static_cast<unsigned int>(i);
    }

    // ---- candidates of every evaluation point from the 27 surrounding bins
    result.columns.reserve(eval_points.size() * 27);
    for (const Point3 &X : eval_points)
      {
        const std::size_t row_begin = result.columns.size();
        std::int64_t      from[3], to[3];
        bool              empty = false;
        for (unsigned int k = 0; k < 3; ++k)
          {
            const double c = bin_coordinate(X[k], k);
            if (!(c >= -1.0 && c <= static_cast<double>(nb[k])))
              {
                empty = true; // farther than one bin from every particle (or not finite)
                break;
              }
            from[k] = std::max<std::int64_t>(static_cast<std::int64_t>(c) - 1, 0);
            to[k]   = std::min<std::int64_t>(static_cast<std::int64_t>(c) + 1, nb[k] - 1);
          }
        if (!empty)
          for (std::int64_t z = from[2]; z <= to[2]; ++z)
            for (std::int64_t y = from[1]; y <= to[1]; ++y)
              for (std::int64_t x = from[0]; x <= to[0]; ++x)
                {
                  const std::size_t bin = static_cast<std::size_t>((z * nb[1] + y) * nb[0] + x);
                  for (unsigned int t = bin_offsets[bin]; t < bin_offsets[bin + 1]; ++t)
                    {
                      const unsigned int I  = bin_particles[t];
                      const Point3      &XI = particle_positions[I];
                      const Point3       r  = {{X[0] - XI[0], X[1] - XI[1], X[2] - XI[2]}};
                      if (inside_support(r, support_radii[I], support))
                        result.columns.push_back(I);
                    }
                }
        std::sort(result.columns.begin() + static_cast<std::ptrdiff_t>(row_begin), result.columns.end());
        if (result.columns.size() > std::numeric_limits<unsigned int>::max())
          throw std::length_error("find_support_neighbors: more entries than unsigned int can index");
        result.row_offsets.push_back(static_cast<unsigned int>(result.columns.size()));
      }
    return result;
  }
} // namespace shard::particles
