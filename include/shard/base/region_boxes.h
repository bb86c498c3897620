// SPDX-License-Identifier: LGPL-2.1-or-later
/**
 * @file region_boxes.h
 * @brief The region of a rank's points as a few tight boxes, for choosing what to send to
 *        which rank (contact halo, particle set-up).
 * @ingroup base
 */
#pragma once

#include <algorithm>
#include <array>
#include <cstddef>
#include <map>
#include <vector>

namespace shard::base
{
  /// A point in m.
  using Point = std::array<double, 3>;

  /**
   * @brief The tight boxes of a set of points in the cells of a grid of at most 8 x 8 x 8
   * cells (cell edge @p min_edge, or an eighth of the largest extent of the points if larger).
   *
   * One box around all points would hold much of another rank's region wherever a partition
   * is not compact (a rank with cells at both ends of a block); at most 512 boxes describe it
   * closely and stay cheap to all-gather. Empty cells have no box. The boxes and the points of
   * each box depend only on the points and @p min_edge.
   */
  class RegionBoxes
  {
  public:
    /// Bins @p points, which must outlive this object (for_each_near() reads them). @p min_edge
    /// is the smallest cell edge (m), typically twice the largest distance at which another
    /// rank's interest is tested.
    RegionBoxes(const std::vector<Point> &points, const double min_edge)
      : points_(points)
    {
      if (points.empty())
        return;
      Point lo = points[0], hi = points[0];
      for (const auto &x : points)
        for (unsigned int c = 0; c < 3; ++c)
          lo[c] = std::min(lo[c], x[c]), hi[c] = std::max(hi[c], x[c]);
      const double extent = std::max({hi[0] - lo[0], hi[1] - lo[1], hi[2] - lo[2]});
      const double edge   = std::max({min_edge, extent / 8., 1e-300});
      std::map<std::array<long, 3>, std::size_t> cell_of;
      for (std::size_t p = 0; p < points.size(); ++p)
        {
          const auto         &x = points[p];
          std::array<long, 3> key;
          for (unsigned int c = 0; c < 3; ++c)
            key[c] = std::min(7L, static_cast<long>((x[c] - lo[c]) / edge));
          auto it = cell_of.find(key);
          if (it == cell_of.end())
            {
              it = cell_of.emplace(key, members_.size()).first;
              members_.emplace_back();
              boxes.insert(boxes.end(), {x[0], x[1], x[2], x[0], x[1], x[2]});
            }
          double *b = &boxes[6 * it->second];
          for (unsigned int c = 0; c < 3; ++c)
            b[c] = std::min(b[c], x[c]), b[3 + c] = std::max(b[3 + c], x[c]);
          members_[it->second].push_back(p);
        }
      // Boxes in the order of the grid cells, so that they do not depend on the point order.
      std::vector<double>                   sorted_boxes;
      std::vector<std::vector<std::size_t>> sorted_members;
      for (const auto &[key, b] : cell_of)
        {
          sorted_boxes.insert(sorted_boxes.end(), &boxes[6 * b], &boxes[6 * b] + 6);
          sorted_members.push_back(std::move(members_[b]));
        }
      boxes.swap(sorted_boxes);
      members_.swap(sorted_members);
    }

    /// 6 doubles per box: lower corner, upper corner (m).
    std::vector<double> boxes;

    /**
     * @brief Calls @p visit(p) once for every point p within @p reach of one of @p others
     * (6 doubles per box) in the max norm (per direction), in ascending cell, then point
     * order. The max norm bounds box supports and spheres alike.
     */
    template <typename Visit>
    void
    for_each_near(const std::vector<double> &others, const double reach, Visit &&visit) const
    {
      std::vector<const double *> near;
      for (std::size_t b = 0; b < members_.size(); ++b)
        {
          near.clear();
          for (std::size_t o = 0; o + 6 <= others.size(); o += 6)
            if (max_norm_gap(&boxes[6 * b], &boxes[6 * b + 3], &others[o], &others[o + 3]) <= reach)
              near.push_back(&others[o]);
          if (near.empty())
            continue;
          for (const std::size_t p : members_[b])
            for (const double *o : near)
              if (max_norm_gap(points_[p].data(), points_[p].data(), o, o + 3) <= reach)
                {
                  visit(p);
                  break;
                }
        }
    }

    /// Largest per-direction gap between the boxes [alo, ahi] and [blo, bhi] (0 where they overlap).
    static double
    max_norm_gap(const double *alo, const double *ahi, const double *blo, const double *bhi)
    {
      double gap = 0;
      for (unsigned int c = 0; c < 3; ++c)
        gap = std::max({gap, blo[c] - ahi[c], alo[c] - bhi[c]});
      return gap;
    }

  private:
    const std::vector<Point>              &points_;
    std::vector<std::vector<std::size_t>> members_;
  };
} // namespace shard::base
