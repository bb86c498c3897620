// SPDX-License-Identifier: LGPL-2.1-or-later
/**
 * @file neighbor_build.h
 * @brief Candidate search for RK stencils by uniform binning of the supports (no deal.II headers).
 * @ingroup particles
 */
#pragma once

#include <shard/particles/rk_shape.h>

#include <vector>

namespace shard::particles
{
  /**
   * @brief For every evaluation point X the particles I whose kernel support contains X:
   * box |X_k - X_kI| < a_kI for k = 1, 2, 3; sphere |D_I^{-1}(X - X_I)| < 1, D_I = diag(a_I)
   * (|X - X_I| < a_I for equal radii). These are exactly the particles with @f$ \Phi_I(X) > 0 @f$
   * up to rounding at the support boundary, where the weight vanishes anyway.
   *
   * Each particle is listed in every cubic bin its support box overlaps; the bin edge is the
   * median support radius, no less than an eighth of the largest (enlarged when needed so that
   * there are at most about 2 N bins), and a point reads only its own bin: O(N + n_eval) expected
   * work for bounded density, also when a few particles have much larger supports than the
   * rest (a graded far field). Evaluation points may lie outside the
   * particles' bounding box. Columns within a row are ascending; a particle position used as
   * evaluation point finds the particle itself.
   *
   * @param eval_points evaluation points in m
   * @param particle_positions X_I in m
   * @param support_radii (a_1I, a_2I, a_3I) per particle in m, all > 0 and finite
   * @param support box or sphere
   * @return CSR pattern with one row per evaluation point
   * @throw std::invalid_argument on inconsistent sizes or invalid radii
   */
  CsrPattern
  find_support_neighbors(const std::vector<Point3> &eval_points,
                         const std::vector<Point3> &particle_positions,
                         const std::vector<Point3> &support_radii,
                         Support                    support);
} // namespace shard::particles
