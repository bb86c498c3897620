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

    // ---- bin geometry. Every particle is listed in each bin its support box overlaps, so a
    // query reads the one bin of its point. The edge b is the median support radius (no less
    // than an eighth of the largest, which bounds the bins per particle to 17^3): a graded cloud
    // (large far-field particles beside small ones) then still reads few candidates per point.
    // At most about 2 N bins: b grows for sparse clouds.
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
    std::vector<double> largest(n);
    for (std::size_t i = 0; i < n; ++i)
      largest[i] = std::max({support_radii[i][0], support_radii[i][1], support_radii[i][2]});
    std::nth_element(largest.begin(), largest.begin() + static_cast<std::ptrdiff_t>(n / 2), largest.end());
    double b = std::max(largest[n / 2], a_max / 8.0);
    for (unsigned int k = 0; k < 3; ++k)
      {
        lo[k] -= a_max;
        hi[k] += a_max;
      }
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
    // The bins a support box overlaps, widened by a relative 1e-9 so that rounding of
    // (x - lo) / b never drops a point inside the support.
    const auto bin_range = [&](const std::size_t i, std::int64_t *from, std::int64_t *to) {
      for (unsigned int k = 0; k < 3; ++k)
        {
          const double c_lo = (particle_positions[i][k] - support_radii[i][k] - lo[k]) / b;
          const double c_hi = (particle_positions[i][k] + support_radii[i][k] - lo[k]) / b;
          from[k] = std::clamp<std::int64_t>(static_cast<std::int64_t>(std::floor(c_lo - 1e-9 * (1 + std::abs(c_lo)))), 0,
                                             nb[k] - 1);
          to[k]   = std::clamp<std::int64_t>(static_cast<std::int64_t>(std::floor(c_hi + 1e-9 * (1 + std::abs(c_hi)))), 0,
                                           nb[k] - 1);
        }
    };

    // ---- counting sort of the (bin, particle) pairs by bin (ascending particle index within a bin)
    std::vector<std::size_t> bin_offsets(n_bins + 1, 0u);
    for (std::size_t i = 0; i < n; ++i)
      {
        std::int64_t from[3], to[3];
        bin_range(i, from, to);
        for (std::int64_t z = from[2]; z <= to[2]; ++z)
          for (std::int64_t y = from[1]; y <= to[1]; ++y)
            for (std::int64_t x = from[0]; x <= to[0]; ++x)
              ++bin_offsets[static_cast<std::size_t>((z * nb[1] + y) * nb[0] + x) + 1];
      }
    for (std::size_t c = 0; c < n_bins; ++c)
      bin_offsets[c + 1] += bin_offsets[c];
    std::vector<unsigned int> bin_particles(bin_offsets[n_bins]);
    {
      std::vector<std::size_t> next(bin_offsets.begin(), bin_offsets.end() - 1);
      for (std::size_t i = 0; i < n; ++i)
        {
          std::int64_t from[3], to[3];
          bin_range(i, from, to);
          for (std::int64_t z = from[2]; z <= to[2]; ++z)
            for (std::int64_t y = from[1]; y <= to[1]; ++y)
              for (std::int64_t x = from[0]; x <= to[0]; ++x)
                bin_particles[next[static_cast<std::size_t>((z * nb[1] + y) * nb[0] + x)]++] =
                  static_cast<unsigned int>(i);
        }
    }

    // ---- candidates of every evaluation point: the particles listed in its bin
    result.columns.reserve(eval_points.size() * 27);
    for (const Point3 &X : eval_points)
      {
        std::int64_t c[3];
        bool         inside = true;
        for (unsigned int k = 0; k < 3; ++k)
          {
            const double v = bin_coordinate(X[k], k);
            if (!(v >= 0.0 && v < static_cast<double>(nb[k])))
              {
                inside = false; // outside every support (or not finite)
                break;
              }
            c[k] = static_cast<std::int64_t>(v);
          }
        if (inside)
          {
            const std::size_t bin = static_cast<std::size_t>((c[2] * nb[1] + c[1]) * nb[0] + c[0]);
            for (std::size_t t = bin_offsets[bin]; t < bin_offsets[bin + 1]; ++t)
              {
                const unsigned int I  = bin_particles[t];
                const Point3      &XI = particle_positions[I];
                const Point3       r  = {{X[0] - XI[0], X[1] - XI[1], X[2] - XI[2]}};
                if (inside_support(r, support_radii[I], support))
                  result.columns.push_back(I);
              }
          }
        if (result.columns.size() > std::numeric_limits<unsigned int>::max())
          throw std::length_error("find_support_neighbors: more entries than unsigned int can index");
        result.row_offsets.push_back(static_cast<unsigned int>(result.columns.size()));
      }
    return result;
  }
} // namespace shard::particles
