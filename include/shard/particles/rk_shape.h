// SPDX-License-Identifier: LGPL-2.1-or-later
/**
 * @file rk_shape.h
 * @brief Reproducing-kernel (RK) shape functions with linear basis and cubic B-spline kernel,
 * stored as fixed CSR stencil arrays.
 * @ingroup particles
 *
 * Pure C++ (no deal.II headers). Formulas: doc/theory/rk_shape_functions.md and
 * formulation.md sections 2 and 6. Units: positions and support radii in m, gradients in 1/m.
 */
#pragma once

#include <array>
#include <cstddef>
#include <string>
#include <vector>

namespace shard::particles
{
  /// A position, a distance vector or three per-direction lengths, in m.
  using Point3 = std::array<double, 3>;

  /**
   * @brief Shape of the kernel support (LS-DYNA ISPLINE 0 and 2).
   *
   * box: tensor product of 1-D splines, support |X_k - X_kI| < a_kI in every direction.
   * sphere: spline of the normalised distance z = |D_I^{-1}(X - X_I)|, D_I = diag(a_1I, a_2I, a_3I);
   * with equal radii a_I this is the sphere |X - X_I| < a_I (unequal radii give an ellipsoid).
   */
  enum class Support
  {
    box,
    sphere
  };

  /**
   * @brief Cubic B-spline of formulation.md section 2,
   * @f$ \phi(z) = 2/3 - 4z^2 + 4z^3 @f$ for @f$ 0 \le z \le 1/2 @f$,
   * @f$ 4/3 - 4z + 4z^2 - (4/3)z^3 = (4/3)(1-z)^3 @f$ for @f$ 1/2 < z \le 1 @f$, 0 beyond.
   *
   * Evaluated in the factorised form on the outer interval so that it is never negative.
   * @param z normalised distance; negative values are taken as |z| (even extension)
   */
  double
  phi(double z);

  /**
   * @brief Derivative of phi(): @f$ -8z + 12z^2 @f$ for @f$ z \le 1/2 @f$,
   * @f$ -4 + 8z - 4z^2 = -4(1-z)^2 @f$ for @f$ 1/2 < z \le 1 @f$, 0 beyond.
   * @param z normalised distance; for negative z the derivative of the even extension (odd) is returned
   */
  double
  dphi(double z);

  /**
   * @brief Kernel value @f$ \Phi_a(r) @f$ for the distance vector r = X - X_I.
   * @param r distance vector X - X_I in m
   * @param a support radii (a_1I, a_2I, a_3I) of the neighbour I in m, all > 0
   * @param support box or sphere
   */
  double
  kernel_value(const Point3 &r, const Point3 &a, Support support);

  /**
   * @brief Kernel value and its gradient @f$ \partial\Phi/\partial X_k @f$ with respect to the
   * evaluation point X (r = X - X_I).
   * @param r distance vector X - X_I in m
   * @param a support radii of the neighbour I in m, all > 0
   * @param support box or sphere
   * @param[out] gradient gradient in 1/m (zero outside the support)
   * @return the kernel value
   */
  double
  kernel_value_and_gradient(const Point3 &r, const Point3 &a, Support support, Point3 &gradient);

  /**
   * @brief Parameters of the RK approximation.
   */
  struct RkParameters
  {
    /// Normalised support size c in a_kI = c h_kI; >= 1, 1.4-1.8 advised (LS-DYNA DX, DY, DZ).
    double dilation = 1.5;
    /// Box (tensor product) or spherical support.
    Support support = Support::box;
    /// Rows whose scaled moment matrix has a reciprocal 2-norm condition number below this use Shepard.
    double rcond_limit = 1e-8;

    /// The support radii a_k = c h_k of a point with spacings @p h (m): the one place a = c h is formed.
    Point3
    support_radius(const Point3 &h) const
    {
      return {{dilation * h[0], dilation * h[1], dilation * h[2]}};
    }

    /**
     * @brief Throws std::invalid_argument naming the key when a value is out of range:
     * dilation < 1 (or not finite), rcond_limit outside [0, 1).
     */
    void
    check() const;

    /**
     * @brief A warning text when the dilation lies outside the advised range 1.4-1.8, empty otherwise.
     */
    std::string
    warning() const;
  };

  /**
   * @brief Support radii a_kI = c h_kI from per-particle spacings (largest incident edge per direction).
   * @param spacing h_kI per particle in m
   * @param params dilation c (checked)
   */
  std::vector<Point3>
  support_radii_from_spacing(const std::vector<Point3> &spacing, const RkParameters &params);

  /**
   * @brief A compressed sparse row pattern: the column indices of row r are
   * columns[row_offsets[r]] ... columns[row_offsets[r+1] - 1].
   */
  struct CsrPattern
  {
    /// n_rows + 1 offsets, first 0, last columns.size().
    std::vector<unsigned int> row_offsets{0u};
    /// Column (particle) index of every entry.
    std::vector<unsigned int> columns;

    /// Number of rows.
    unsigned int
    n_rows() const
    {
      return row_offsets.empty() ? 0u : static_cast<unsigned int>(row_offsets.size() - 1);
    }
  };

  /**
   * @brief Fixed CSR arrays of RK shape functions: row J = evaluation point X_J, entry = neighbour K,
   * @f$ \Psi_K(X_J) @f$ and @f$ \nabla\Psi_K(X_J) @f$.
   */
  struct Stencil
  {
    /// n_rows + 1 offsets into columns, psi and (times 3) grad.
    std::vector<unsigned int> row_offsets{0u};
    /// Neighbour (particle) index of every entry; within a row in the order of the candidate list.
    std::vector<unsigned int> columns;
    /// @f$ \Psi_K(X_J) @f$, one per entry (dimensionless).
    std::vector<double> psi;
    /// @f$ \partial\Psi_K/\partial X_k (X_J) @f$, three per entry (entry-major), in 1/m.
    std::vector<double> grad;
    /// Per row: 1 when the Shepard fallback was used (ill-conditioned, fewer than 4 weights, or empty).
    std::vector<unsigned char> fallback;
    /// Per row: reciprocal 2-norm condition number of the scaled moment matrix (0 for an empty row).
    std::vector<double> rcond;
    /// Number of columns (particles) the column indices refer to.
    unsigned int n_columns = 0;

    /// Number of rows.
    unsigned int
    n_rows() const
    {
      return row_offsets.empty() ? 0u : static_cast<unsigned int>(row_offsets.size() - 1);
    }

    /// Number of entries.
    std::size_t
    n_entries() const
    {
      return columns.size();
    }
  };

  /**
   * @brief Column-wise index of a Stencil, so that a scatter @f$ f_K = \sum_J \Psi_K(X_J) g_J @f$
   * is written as a gather over column K.
   *
   * For column K the pairs (rows[t], entries[t]), t = column_offsets[K] ... column_offsets[K+1] - 1,
   * list every entry of the stencil in column K, rows ascending; entries[t] indexes
   * Stencil::columns, Stencil::psi and (times 3) Stencil::grad.
   */
  struct TransposedIndex
  {
    /// n_columns + 1 offsets.
    std::vector<unsigned int> column_offsets{0u};
    /// Row of every transposed entry.
    std::vector<unsigned int> rows;
    /// Stencil entry of every transposed entry.
    std::vector<unsigned int> entries;
  };

  /**
   * @brief Builds the transposed index of @p stencil (counting sort, O(n_entries + n_columns)).
   * @param stencil a stencil with valid row_offsets, columns and n_columns
   */
  TransposedIndex
  build_transposed_index(const Stencil &stencil);

  /**
   * @brief RK shape functions (linear basis) and their gradients at evaluation points.
   *
   * Per evaluation point X: the moment matrix M of the basis H = [1, (X - X_I)/s] (s_k the largest
   * support radius a_kI of the contributing neighbours in direction k) and its three derivatives are
   * accumulated in one pass; the reciprocal condition number of M is taken from its eigenvalues
   * (cyclic Jacobi); M is factorised by LDL^T with a pivot check. Rows with fewer than 4 neighbours
   * of nonzero weight, rcond < params.rcond_limit or a failed pivot use Shepard functions
   * @f$ \Phi_I / \sum_L \Phi_L @f$ with their exact gradient and are flagged. The pattern is the
   * candidate pattern @p neighbors (candidates outside the support get zero entries).
   * No heap allocation per evaluation point.
   *
   * @param eval_points evaluation points X_J in m (a particle position includes the particle itself)
   * @param particle_positions X_I in m
   * @param support_radii (a_1I, a_2I, a_3I) per particle in m, all > 0; the support of the kernel
   *        belongs to the neighbour I
   * @param neighbors candidate particles per evaluation point (e.g. from find_support_neighbors())
   * @param params support shape and condition limit (checked)
   * @throw std::invalid_argument on inconsistent sizes, indices or radii, or invalid params
   */
  Stencil
  build_rk_stencil(const std::vector<Point3> &eval_points,
                   const std::vector<Point3> &particle_positions,
                   const std::vector<Point3> &support_radii,
                   const CsrPattern          &neighbors,
                   const RkParameters        &params);

  /**
   * @brief Inverse of a symmetric positive definite 4x4 matrix (row-major, 16 doubles) by the
   * LDL^T factorisation the moment matrices use.
   * @return false, leaving @p inverse untouched, when a pivot is not clearly positive
   */
  bool
  invert_spd4(const double *matrix, double *inverse);
} // namespace shard::particles
