// SPDX-License-Identifier: LGPL-2.1-or-later
// Contact geometry kernels and binned neighbour search: see include/shard/contact/contact_geometry.h.
#include <shard/contact/contact_geometry.h>

#include <cmath>
#include <limits>
#include <stdexcept>

namespace shard::contact
{
  namespace
  {
    Vec3
    difference(const Vec3 &a, const Vec3 &b)
    {
      return Vec3{{a[0] - b[0], a[1] - b[1], a[2] - b[2]}};
    }

    double
    dot(const Vec3 &a, const Vec3 &b)
    {
      return a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
    }

    Vec3
    cross(const Vec3 &a, const Vec3 &b)
    {
      return Vec3{{a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]}};
    }

    /// Relative size below which a triangle of the segment split counts as degenerate.
    constexpr double degenerate_ratio = 1e-12;
  } // namespace


  SegmentHit
  point_segment(const Vec3 &p, const std::array<Vec3, 4> &x, const double max_depth, const double edge_tolerance)
  {
    Vec3 c{};
    for (unsigned int k = 0; k < 3; ++k)
      c[k] = 0.25 * (x[0][k] + x[1][k] + x[2][k] + x[3][k]);

    SegmentHit result;
    bool       found    = false;
    double     best_abs = std::numeric_limits<double>::infinity();
    for (unsigned int a = 0; a < 4; ++a)
      {
        const unsigned int b     = (a + 1) % 4;
        const Vec3         e1    = difference(x[b], x[a]);
        const Vec3         e2    = difference(c, x[a]);
        const Vec3         N     = cross(e1, e2);
        const double       NN    = dot(N, N);
        const double       scale = degenerate_ratio * (dot(e1, e1) + dot(e2, e2));
        if (!(NN > scale * scale))
          continue;

        // Barycentric coordinates of the projection q = p - gap n (the normal part of d drops out).
        const Vec3   d        = difference(p, x[a]);
        const double lambda_b = dot(cross(d, e2), N) / NN;
        const double lambda_c = dot(cross(e1, d), N) / NN;
        const double lambda_a = 1.0 - lambda_b - lambda_c;
        if (!(lambda_a >= -edge_tolerance && lambda_b >= -edge_tolerance && lambda_c >= -edge_tolerance))
          continue;

        const double inv_norm = 1.0 / std::sqrt(NN);
        const Vec3   n{{N[0] * inv_norm, N[1] * inv_norm, N[2] * inv_norm}};
        const double gap = dot(d, n);
        if (found && !(std::abs(gap) < best_abs))
          continue;

        double       la  = std::max(lambda_a, 0.0);
        double       lb  = std::max(lambda_b, 0.0);
        double       lc  = std::max(lambda_c, 0.0);
        const double sum = la + lb + lc;
        la /= sum;
        lb /= sum;
        lc /= sum;

        found         = true;
        best_abs      = std::abs(gap);
        result.gap    = gap;
        result.normal = n;
        result.weights.fill(0.25 * lc);
        result.weights[a] += la;
        result.weights[b] += lb;
      }

    result.projected = found;
    result.hit       = found && -max_depth < result.gap && result.gap < 0.0;
    return result;
  }


  SphereHit
  sphere_pair(const Vec3 &xi, const Vec3 &xj, const double ri, const double rj)
  {
    const Vec3   d        = difference(xj, xi);
    const double distance = std::sqrt(dot(d, d));
    SphereHit    result;
    result.overlap = ri + rj - distance;
    if (distance > 0.0)
      for (unsigned int k = 0; k < 3; ++k)
        result.normal[k] = d[k] / distance;
    return result;
  }


  double
  plane_gap(const Vec3 &p, const Vec3 &point, const Vec3 &normal)
  {
    return dot(difference(p, point), normal);
  }


  Vec3
  coulomb_friction(const Vec3 &v_rel, const Vec3 &n, const double normal_force, const double mu, const double v_eps)
  {
    Vec3 vt = v_rel;
    // Two projections: the second removes the normal part left by rounding in the first.
    for (unsigned int pass = 0; pass < 2; ++pass)
      {
        const double vn = dot(vt, n);
        for (unsigned int k = 0; k < 3; ++k)
          vt[k] -= vn * n[k];
      }
    const double speed = std::sqrt(dot(vt, vt));
    const double denom = std::max(speed, v_eps);
    if (!(denom > 0.0))
      return Vec3{};
    const double factor = std::max(mu, 0.0) * std::max(normal_force, 0.0) / denom;
    return Vec3{{-factor * vt[0], -factor * vt[1], -factor * vt[2]}};
  }


  void
  BinGrid::build(const std::vector<Vec3> &points, const double cell_size)
  {
    if (!(cell_size > 0.0) || !std::isfinite(cell_size))
      throw std::invalid_argument("BinGrid::build: cell_size must be positive and finite");
    if (points.size() >= std::numeric_limits<unsigned int>::max())
      throw std::invalid_argument("BinGrid::build: too many points for unsigned int indices");

    Vec3 lo{}, hi{};
    if (!points.empty())
      {
        lo = points[0];
        hi = points[0];
      }
    for (const Vec3 &x : points)
      for (unsigned int k = 0; k < 3; ++k)
        {
          if (!std::isfinite(x[k]))
            throw std::invalid_argument("BinGrid::build: point coordinates must be finite");
          lo[k] = std::min(lo[k], x[k]);
          hi[k] = std::max(hi[k], x[k]);
        }
    Vec3   extent{};
    double max_extent = 0.0;
    for (unsigned int k = 0; k < 3; ++k)
      {
        extent[k] = hi[k] - lo[k];
        if (!std::isfinite(extent[k]))
          throw std::invalid_argument("BinGrid::build: bounding box of the points too large");
        max_extent = std::max(max_extent, extent[k]);
      }

    cell_offsets_.clear();
    sorted_index_.clear();
    sorted_position_.clear();
    origin_ = lo;
    upper_  = hi;
    if (points.empty())
      {
        cell_size_ = cell_size;
        n_         = {{0, 0, 0}};
        return;
      }

    // ---- cell size: grow until at most 8 n + 64 cells are needed
    const std::size_t n_points = points.size();
    const double      cap      = 8.0 * static_cast<double>(n_points) + 64.0;
    double            h        = cell_size;
    // No cell size below max_extent / cap can satisfy the cap (one direction alone needs more cells).
    if (max_extent / h > cap)
      h = max_extent / cap;
    for (;;)
      {
        double total = 1.0;
        for (unsigned int k = 0; k < 3; ++k)
          total *= std::floor(extent[k] / h) + 1.0;
        if (total <= cap)
          break;
        h *= std::max(1.05, std::cbrt(total / cap));
      }
    cell_size_ = h;
    for (unsigned int k = 0; k < 3; ++k)
      n_[k] = static_cast<std::size_t>(std::floor(extent[k] / h)) + 1;
    const std::size_t n_cells = n_[0] * n_[1] * n_[2];

    // ---- counting sort by cell, stable (ascending point index within a cell)
    std::vector<std::size_t> cell_of(n_points);
    cell_offsets_.assign(n_cells + 1, 0u);
    for (std::size_t i = 0; i < n_points; ++i)
      {
        const Vec3 &x = points[i];
        cell_of[i]    = cell_coordinate(x[0], 0) + n_[0] * (cell_coordinate(x[1], 1) + n_[1] * cell_coordinate(x[2], 2));
        ++cell_offsets_[cell_of[i] + 1];
      }
    for (std::size_t c = 0; c < n_cells; ++c)
      cell_offsets_[c + 1] += cell_offsets_[c];

    sorted_index_.resize(n_points);
    sorted_position_.resize(n_points);
    std::vector<unsigned int> next(cell_offsets_.begin(), cell_offsets_.end() - 1);
    for (std::size_t i = 0; i < n_points; ++i)
      {
        const unsigned int t = next[cell_of[i]]++;
        sorted_index_[t]     = static_cast<unsigned int>(i);
        sorted_position_[t]  = points[i];
      }
  }


  unsigned int
  BinGrid::size() const
  {
    return static_cast<unsigned int>(sorted_index_.size());
  }


  std::size_t
  BinGrid::n_cells() const
  {
    return n_[0] * n_[1] * n_[2];
  }


  double
  BinGrid::cell_size() const
  {
    return cell_size_;
  }
} // namespace shard::contact
