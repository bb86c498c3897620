// SPDX-License-Identifier: LGPL-2.1-or-later
/**
 * @file contact_geometry.h
 * @brief Contact geometry kernels (point against quadrilateral segment, sphere pairs, planes),
 * regularized Coulomb friction and a uniform-grid neighbour search.
 * @ingroup contact
 *
 * Pure C++17 (no deal.II headers). All positions, distances and gaps are in m, velocities in m/s,
 * forces in N; weights, barycentric coordinates and friction coefficients are dimensionless.
 * Every kernel works on the current (deformed) configuration.
 */
#pragma once

#include <algorithm>
#include <array>
#include <cmath>
#include <cstddef>
#include <utility>
#include <vector>

namespace shard::contact
{
  /// A position, a direction or a velocity in 3-D (m, dimensionless or m/s, as stated at each use).
  using Vec3 = std::array<double, 3>;

  /**
   * @brief Result of a point against one quadrilateral contact segment (see point_segment()).
   *
   * When no triangle of the segment has a projection that counts as on it, all members keep their
   * default values (hit and projected false, gap 0, normal and weights zero). When a projection
   * counts but the gap is outside (-max_depth, 0), hit is false, projected true and the other
   * members describe that projection.
   */
  struct SegmentHit
  {
    /// True when the point penetrates: -max_depth < gap < 0 and the projection lies on the segment.
    bool hit = false;
    /// True when the projection lies on the segment (any gap); gap, normal and weights then
    /// describe it.
    bool projected = false;
    /// Signed normal distance @f$ (p - q)\cdot n @f$ in m; negative means penetration.
    double gap = 0;
    /// Unit outward normal (dimensionless) of the triangle that was hit.
    Vec3 normal{};
    /**
     * Weights (dimensionless) of the 4 segment nodes for the contact point
     * @f$ q = \sum_a w_a x_a @f$: they sum to 1 and are all >= 0, so that the reaction on node a
     * to a force f on the point is @f$ -w_a f @f$.
     */
    std::array<double, 4> weights{};
  };

  /**
   * @brief Point @p p against the bilinear quadrilateral segment @p x.
   *
   * The quad is split into the 4 triangles @f$ (x_a, x_{a+1}, c) @f$, a = 0..3 (indices modulo 4),
   * with the centroid @f$ c = \frac14 \sum_a x_a @f$. For each triangle (skipped when degenerate)
   * the point is projected along the triangle's unit outward normal
   * @f$ n = (x_{a+1} - x_a) \times (c - x_a) / |\cdot| @f$ onto q = p - gap n with
   * gap = (p - x_a) . n. The projection counts as on the triangle when all three barycentric
   * coordinates are >= -@p edge_tolerance; they are then clamped to >= 0 and renormalized to sum 1.
   * Among the triangles whose projection counts the one with the smallest |gap| is taken (the first
   * on ties). The centroid's barycentric coordinate is shared equally by the 4 nodes, so for an
   * unclamped projection @f$ \sum_a w_a x_a = q @f$ holds exactly in exact arithmetic, which makes
   * the node reactions balance the moment of a force along n through q.
   *
   * @param p position of the slave point in m
   * @param x current node positions in m, ordered counter-clockwise seen from outside (the outward
   *        normal follows the right-hand rule)
   * @param max_depth largest penetration in m that still counts as a hit (> 0)
   * @param edge_tolerance tolerance on the barycentric coordinates (dimensionless, relative to the
   *        triangle), default 1e-3
   * @return the hit information; hit requires -max_depth < gap < 0
   */
  SegmentHit
  point_segment(const Vec3 &p, const std::array<Vec3, 4> &x, double max_depth, double edge_tolerance = 1e-3);

  /**
   * @brief Result of two spheres against each other (see sphere_pair()).
   */
  struct SphereHit
  {
    /// Overlap @f$ r_i + r_j - |x_j - x_i| @f$ in m; positive means contact.
    double overlap = 0;
    /// Unit normal @f$ (x_j - x_i)/|x_j - x_i| @f$ from sphere i to sphere j (dimensionless);
    /// (0, 0, 0) for coincident centres.
    Vec3 normal{};
  };

  /**
   * @brief Overlap and normal of two spheres.
   * @param xi centre of sphere i in m
   * @param xj centre of sphere j in m
   * @param ri radius of sphere i in m
   * @param rj radius of sphere j in m
   * @return overlap ri + rj - |xj - xi| and the unit normal from i to j; for coincident centres the
   *         normal is (0, 0, 0) and the overlap ri + rj
   */
  SphereHit
  sphere_pair(const Vec3 &xi, const Vec3 &xj, double ri, double rj);

  /**
   * @brief Signed distance of a point from a plane.
   * @param p the point in m
   * @param point a point of the plane in m
   * @param normal unit normal of the plane (dimensionless)
   * @return @f$ (p - \mathrm{point})\cdot \mathrm{normal} @f$ in m, positive on the side the normal
   *         points to
   */
  double
  plane_gap(const Vec3 &p, const Vec3 &point, const Vec3 &normal);

  /**
   * @brief Regularized Coulomb friction force on the slave.
   *
   * With the tangential relative velocity @f$ v_t = v_{rel} - (v_{rel}\cdot n) n @f$ (projected
   * twice, so that its normal component is at rounding level of |v_t| itself) the force is
   * @f$ f_t = -\mu F_n v_t / \max(|v_t|, v_\varepsilon) @f$: of magnitude @f$ \mu F_n @f$ when
   * @f$ |v_t| \ge v_\varepsilon @f$, linear in v_t below. The dissipation @f$ f_t\cdot v_t \le 0 @f$
   * always; negative @p normal_force or @p mu are treated as 0. Returns zero when both |v_t| and
   * @p v_eps are zero.
   *
   * @param v_rel relative velocity slave minus master in m/s
   * @param n unit contact normal (dimensionless)
   * @param normal_force magnitude of the normal contact force in N (>= 0)
   * @param mu Coulomb friction coefficient (dimensionless, >= 0)
   * @param v_eps regularization velocity in m/s (> 0)
   * @return the friction force on the slave in N (the master receives its negative)
   */
  Vec3
  coulomb_friction(const Vec3 &v_rel, const Vec3 &n, double normal_force, double mu, double v_eps);

  /**
   * @brief Uniform-grid binning of points for neighbour queries in the current configuration.
   *
   * The points are sorted into cubic cells covering their bounding box (counting sort, cell offsets
   * in CSR form, positions stored in cell order). A box query visits only the cells the box
   * touches. Memory O(n_points + n_cells).
   */
  class BinGrid
  {
  public:
    /**
     * @brief Bins @p points into cubic cells of edge @p cell_size over their bounding box.
     *
     * The number of cells is capped at 8 n_points + 64: when the box would need more, the cell size
     * is grown until it fits. Deterministic; replaces any previous content.
     * @param points positions in m (all coordinates finite)
     * @param cell_size requested cell edge in m (> 0 and finite)
     * @throw std::invalid_argument when cell_size is not > 0 and finite, when a coordinate is not
     *        finite, or when there are too many points for unsigned int indices
     */
    void
    build(const std::vector<Vec3> &points, double cell_size);

    /**
     * @brief Calls visit(index) once for every binned point whose position lies inside the
     * axis-aligned box [lo, hi] (inclusive in every direction), in ascending index order.
     *
     * Nothing is visited when lo[k] > hi[k] in some direction. The indices are gathered into a
     * per-thread buffer that is reused between calls (no heap allocation once it is large enough;
     * nested calls from @p visit are allowed) and sorted before visiting.
     * @param lo lower corner of the box in m
     * @param hi upper corner of the box in m
     * @param visit callable taking an unsigned int point index
     */
    template <typename Visit>
    void
    for_each_in_box(const Vec3 &lo, const Vec3 &hi, Visit &&visit) const;

    /**
     * @brief Calls visit(i, j) once for every unordered pair of binned points in the same cell or
     * in two cells that share a face, an edge or a corner, so every pair closer than
     * cell_size() is visited (and more; the caller tests the distance).
     *
     * Each cell is paired with itself and its 13 neighbours ahead of it in the linear order (a
     * half stencil), so no pair is visited twice and nothing is sorted. The order of the calls
     * follows the cells, not the point indices; i and j come in either order.
     * @param visit callable taking two unsigned int point indices
     */
    template <typename Visit>
    void
    for_each_neighbour_pair(Visit &&visit) const;

    /// Number of binned points.
    unsigned int
    size() const;

    /// Number of cells of the grid (0 before build() or for no points).
    std::size_t
    n_cells() const;

    /// Cell edge in m actually used (>= the requested one; 0 before build()).
    double
    cell_size() const;

  private:
    /// Cell coordinate in direction k of the coordinate value v, clamped to [0, n_k - 1]. Monotone
    /// in v, which keeps box queries exact at cell boundaries.
    std::size_t
    cell_coordinate(double v, unsigned int k) const
    {
      const double t = std::floor((v - origin_[k]) / cell_size_);
      if (!(t > 0.0))
        return 0;
      const double last = static_cast<double>(n_[k] - 1);
      if (t >= last)
        return n_[k] - 1;
      return static_cast<std::size_t>(t);
    }

    /// Lower corner of the bounding box of the points in m (cell (0, 0, 0) starts here).
    Vec3 origin_{};
    /// Upper corner of the bounding box of the points in m.
    Vec3 upper_{};
    /// Cell edge in m.
    double cell_size_ = 0.0;
    /// Number of cells per direction.
    std::array<std::size_t, 3> n_{{0, 0, 0}};
    /// n_cells + 1 offsets into sorted_index_ and sorted_position_; cell (i, j, k) has the linear
    /// index i + n_0 (j + n_1 k).
    std::vector<unsigned int> cell_offsets_;
    /// Point indices in cell order, ascending within a cell.
    std::vector<unsigned int> sorted_index_;
    /// Point positions in m in the same order as sorted_index_.
    std::vector<Vec3> sorted_position_;
  };


  template <typename Visit>
  void
  BinGrid::for_each_in_box(const Vec3 &lo, const Vec3 &hi, Visit &&visit) const
  {
    if (sorted_index_.empty())
      return;
    for (unsigned int k = 0; k < 3; ++k)
      if (!(lo[k] <= hi[k]) || hi[k] < origin_[k] || lo[k] > upper_[k])
        return;

    std::array<std::size_t, 3> first{}, last{};
    for (unsigned int k = 0; k < 3; ++k)
      {
        first[k] = cell_coordinate(lo[k], k);
        last[k]  = cell_coordinate(hi[k], k);
      }

    // The buffer is moved out of the thread-local slot while in use, so that a nested call from
    // visit() finds the slot empty and works on its own buffer.
    thread_local std::vector<unsigned int> slot;
    std::vector<unsigned int>              found = std::move(slot);
    found.clear();

    for (std::size_t ck = first[2]; ck <= last[2]; ++ck)
      for (std::size_t cj = first[1]; cj <= last[1]; ++cj)
        {
          const std::size_t row = n_[0] * (cj + n_[1] * ck);
          for (std::size_t t = cell_offsets_[row + first[0]]; t < cell_offsets_[row + last[0] + 1]; ++t)
            {
              const Vec3 &x = sorted_position_[t];
              if (lo[0] <= x[0] && x[0] <= hi[0] && lo[1] <= x[1] && x[1] <= hi[1] && lo[2] <= x[2] &&
                  x[2] <= hi[2])
                found.push_back(sorted_index_[t]);
            }
        }

    std::sort(found.begin(), found.end());
    for (const unsigned int index : found)
      visit(index);

    found.clear();
    if (found.capacity() > slot.capacity())
      slot = std::move(found);
  }


  template <typename Visit>
  void
  BinGrid::for_each_neighbour_pair(Visit &&visit) const
  {
    if (sorted_index_.empty())
      return;
    // The 13 offsets (di, dj, dk) ahead of (0, 0, 0) in the order k, then j, then i.
    static constexpr int ahead[13][3] = {{1, 0, 0},  {-1, 1, 0}, {0, 1, 0},  {1, 1, 0},  {-1, -1, 1},
                                         {0, -1, 1}, {1, -1, 1}, {-1, 0, 1}, {0, 0, 1},  {1, 0, 1},
                                         {-1, 1, 1}, {0, 1, 1},  {1, 1, 1}};
    const long n0 = static_cast<long>(n_[0]), n1 = static_cast<long>(n_[1]), n2 = static_cast<long>(n_[2]);
    for (long ck = 0; ck < n2; ++ck)
      for (long cj = 0; cj < n1; ++cj)
        for (long ci = 0; ci < n0; ++ci)
          {
            const std::size_t c = ci + n0 * (cj + n1 * ck);
            const unsigned int begin = cell_offsets_[c], end = cell_offsets_[c + 1];
            if (begin == end)
              continue;
            for (unsigned int t = begin; t < end; ++t)
              for (unsigned int u = t + 1; u < end; ++u)
                visit(sorted_index_[t], sorted_index_[u]);
            for (const auto &o : ahead)
              {
                const long i = ci + o[0], j = cj + o[1], k = ck + o[2];
                if (i < 0 || i >= n0 || j < 0 || j >= n1 || k >= n2)
                  continue;
                const std::size_t d = i + n0 * (j + n1 * k);
                for (unsigned int t = begin; t < end; ++t)
                  for (unsigned int u = cell_offsets_[d]; u < cell_offsets_[d + 1]; ++u)
                    visit(sorted_index_[t], sorted_index_[u]);
              }
          }
  }
} // namespace shard::contact
