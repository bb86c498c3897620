// SPDX-License-Identifier: LGPL-2.1-or-later
/**
 * @file tensor.h
 * @brief Small 3x3 tensor kinematics shared by elements, particles and failure criteria:
 *        incremental rotation, rotation of a symmetric tensor, eigenvalues, principal stretches.
 * @ingroup base
 */
#pragma once

#include <array>

namespace shard::tensor
{
  /**
   * @brief Hughes-Winget incremental rotation
   * @f$ Q = (I - \tfrac12 \Delta t W)^{-1} (I + \tfrac12 \Delta t W) @f$ from the spin
   * @p W (3x3, skew) and @p dt, as a Cayley transform of the axial vector.
   */
  void
  hughes_winget_rotation(const double (&W)[3][3], double dt, double (&Q)[3][3]);

  /// Rotates a symmetric tensor in 6-component storage: s <- Q s Q^T.
  void
  rotate_symmetric(const double (&Q)[3][3], double *s);

  /**
   * @brief Eigenvalues of a symmetric tensor in 6-component storage (xx, yy, zz, yz, xz, xy),
   * ascending, by the trigonometric solution of the characteristic equation (exact for a
   * diagonal tensor; all equal to the mean when the deviator is below 1e-15 of it).
   */
  std::array<double, 3>
  symmetric_eigenvalues(const double *s);

  /// Principal stretches of F (row-major): square roots of the eigenvalues of F^T F, ascending.
  std::array<double, 3>
  principal_stretches(const double *F);
} // namespace shard::tensor
