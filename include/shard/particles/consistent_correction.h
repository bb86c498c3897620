// SPDX-License-Identifier: LGPL-2.1-or-later
/**
 * @file consistent_correction.h
 * @brief The variationally consistent gradient correction: its operator, coarse space and the
 *        preconditioned conjugate-gradient solve (doc/theory/spg_stabilization.md, decision 0009).
 * @ingroup particles
 */
#pragma once

#include <shard/particles/local_stencils.h>
#include <shard/particles/rk_shape.h>

#include <functional>
#include <vector>

namespace shard::particles
{
  /**
   * @brief A coarse space for the consistent-correction solve, given per particle J of the local
   * stencils (owned first): J belongs to one aggregate, whose coarse functions are numbered
   * first[J] .. first[J] + count[J] - 1 over all ranks. Function 0 is 1, functions 1..3 are
   * linear (their values at J in phi); an aggregate too flat or too small for a direction has fewer.
   */
  struct CoarseFunctions
  {
    std::vector<unsigned int>  first;
    std::vector<unsigned char> count;
    /// 3 per J: the linear functions 1..3 of J's aggregate at X_J (0 where count <= k).
    std::vector<double> phi;
  };

  /// One entry of a coarse matrix.
  struct CoarseEntry
  {
    unsigned int row, column;
    double       value;
  };

  /**
   * @brief The consistent gradient correction: the smallest change C of the nodal gradients
   * (same stencils) such that
   * - every row still differentiates linear fields exactly: sum_J C_IJ = 0 and
   *   sum_J C_IJ (x) X_J = 0, so strain reproduction and rigid rotations are untouched;
   * - nodal integration meets the integration constraint sum_I V_I (G + C)_IJ = a_J, with a_J
   *   the outward area vector of particle J (zero inside the body).
   *
   * Used for both trial and test functions, it keeps the stiffness symmetric. Minimizing
   * sum |C_IJ|^2 under these conditions gives C_IJ = V_I [(1 - P_I) lambda]_J, with P_I the
   * Euclidean projection onto linear functions over row I's stencil and lambda (3 per particle,
   * one per gradient direction) a solution of S lambda = r:
   * S = sum_I V_I^2 E_I^T (1 - P_I) E_I (symmetric positive semi-definite; null space: the
   * fields that are linear over every stencil), r_J = a_J - sum_I V_I G_IJ. Because nodal
   * volumes and area vectors integrate linear functions exactly (sum_I V_I = V,
   * sum_J a_J (x) X_J = V 1), r is orthogonal to that null space and the system is consistent.
   * Derivation and evidence: doc/theory/spg_stabilization.md.
   *
   * Arrays over J hold 3 doubles per particle J of the local stencils (owned first); products
   * over the owned rows are partial sums across ranks.
   */
  class ConsistentCorrection
  {
  public:
    /**
     * @param stencils the local stencils (must outlive this object)
     * @param position_j reference positions of the n_j particles J
     * @param volume V_I of the owned rows
     * @param fixed optional, per owned row: nonzero for a row whose gradients are given (a patch
     *        solve: the stencils hold the row's final values). A fixed row enters the defect with
     *        its values and is not corrected (like a row whose stencil does not span 3-D);
     *        corrected_gradients() returns it unchanged.
     */
    ConsistentCorrection(const LocalStencils &stencils, const std::vector<Point3> &position_j, const double *volume,
                         const std::vector<char> *fixed = nullptr);

    /// Partial r_J = a_J - sum_I V_I G_IJ (a_J added for owned J only); @p area 3 per owned row.
    void
    defect(const double *area, double *r) const;

    /// Partial y = S lambda (3 per J); @p lambda must hold values on every J.
    void
    apply(const double *lambda, double *y) const;

    /// Partial diagonal of S, repeated 3 times per J.
    void
    diagonal(double *diag) const;

    /// G + C for a solution @p lambda (values on every J), in the layout of LocalStencils::g.
    std::vector<double>
    corrected_gradients(const double *lambda) const;

    /// Largest entry of a row's correction times l_I, the row's largest coordinate distance in
    /// its stencil (doc/theory/spg_stabilization.md, "Correction limiter").
    static constexpr double max_correction_ratio = 4.;

    /// Rows whose correction the last corrected_gradients() scaled down so that no entry
    /// exceeds max_correction_ratio / l_I.
    unsigned int
    limited_rows() const
    {
      return limited_rows_;
    }

    /// Number of rows J.
    unsigned int
    n_j() const
    {
      return n_j_;
    }

    /// Number of owned rows I.
    unsigned int
    n_i() const
    {
      return n_i_;
    }

    /// Volume V_I of owned row @p i.
    double
    volume(const unsigned int i) const
    {
      return volume_[i];
    }

    /**
     * @brief Partial Galerkin coarse operator Z^T S Z of the owned rows, for a coarse space Z of
     * functions given per particle J (CoarseFunctions). With z_J the values of the functions of
     * J's aggregate at J, a row contributes V_I^2 [sum_J z_J z_J^T (block diagonal per aggregate)
     * - T^T M_I^-1 T], T = sum_J p_J z_J^T: the same projection as apply(), without forming
     * (1 - P_I) Z. Rows whose stencil lies in one aggregate add nothing (its functions are linear).
     * @return the entries (global coarse indices), one per (row, column), in block order (4 x 4 blocks
     *         by (aggregate, aggregate)), without duplicates
     */
    std::vector<CoarseEntry>
    coarse_operator(const CoarseFunctions &functions) const;

  private:
    const LocalStencils &st_;
    unsigned int         n_i_, n_j_;
    std::vector<double>  volume_;
    /// Per stencil entry of G: the linear basis (1, (X_J - X_I) / l_I), 4 doubles.
    std::vector<double> basis_;
    /// Per owned row: the inverse moment matrix of the basis over the stencil, 16 doubles.
    std::vector<double> inverse_moment_;
    /// Per owned row: l_I, the largest coordinate distance from X_I within its stencil.
    std::vector<double> row_length_;
    /// Rows limited by the last corrected_gradients().
    mutable unsigned int limited_rows_ = 0;

    /// mu_I = M_I^-1 sum_J p_J lambda_J (4 x 3, row-major) for row @p i.
    void
    row_fit(unsigned int i, const double *lambda, double *mu) const;
  };

  /// How ranks combine the arrays over J during the correction solve (identity on one rank).
  struct CorrectionExchange
  {
    /// Partial sums over the local J -> totals on owned J and the owners' totals on the others.
    std::function<void(std::vector<double> &)> assemble;
    /// Owned values -> the other J get their owners' values.
    std::function<void(std::vector<double> &)> distribute;
    /// Element-wise sum over ranks.
    std::function<void(std::vector<double> &)> sum;
    /// The vectors of all ranks, concatenated in rank order on rank 0; empty on the others (unset:
    /// one rank, identity). The coarse problem of the solve lives on rank 0 only.
    std::function<std::vector<double>(const std::vector<double> &)> to_root;
    /// The inverse of to_root: rank 0 passes the concatenation and the length of every rank's
    /// part; every rank gets its own part (length @p n_mine). The other ranks wait without spinning
    /// while rank 0 works (unset: one rank, identity).
    std::function<std::vector<double>(const std::vector<double> &all, const std::vector<int> &lengths,
                                      unsigned int n_mine)>
      from_root;
    /// This rank's index (0 on one rank).
    unsigned int rank = 0;
  };

  /// Outcome of the correction solve.
  struct CorrectionSolve
  {
    unsigned int iterations = 0;
    /// |r| before and |r - S lambda| after, Euclidean over all particles (m^2).
    double initial_defect = 0, final_defect = 0;
    /// Part of r outside the range of S that was removed, |r_removed| / |r|.
    double inconsistency = 0;
    bool   converged     = false;
    /// Size of the coarse space of the preconditioner (0: Jacobi alone) and its aggregates.
    unsigned int coarse_functions = 0, aggregates = 0;
  };

  /**
   * @brief Solves S lambda = r by preconditioned conjugate gradients, after removing from r its
   * (round-off or mesh-distortion) component along linear fields, per @p component (e.g. body)
   * of the owned particles.
   *
   * The preconditioner is Jacobi, plus, for @p coarse_size > 0, a coarse space Z with
   * E = Z^T S Z: the owned particles are grouped into aggregates (cubes of edge coarse_size times
   * the mean particle spacing, per component, over all ranks: the same coarse space at any rank
   * count) and Z holds a constant and up to three linear functions per aggregate. With the coarse
   * space the solve starts from Q r (Q = Z E^-1 Z^T) and preconditions with
   * z = w + Q (r - S w), w = D^-1 r (two-level "A-DEF2"; one more product with S per
   * iteration). S is a fourth-order operator, so Jacobi alone needs iterations growing as
   * (L/h)^2 with the size L of the particle set; the coarse space bounds them by the aggregate
   * size (decision 0009, doc/theory/spg_stabilization.md).
   * @param lambda on return, the solution on every J (3 per J)
   * @param tolerance on |r - S lambda| / |r|
   * @param coarse_size aggregate edge in mean particle spacings (0: no coarse space)
   * @param patch a patch solve: only the particles J in the stencil of a corrected (not fixed)
   *        row are unknowns; the others (zero diagonal of S) are left out of the null-space
   *        projection and of the coarse space, and keep lambda = 0. Their defect (what the fixed
   *        rows leave there) is not part of this solve's residual or tolerance: the caller checks
   *        the constraint there afterwards.
   */
  CorrectionSolve
  solve_consistent_correction(const ConsistentCorrection &correction, const double *area,
                              const std::vector<Point3> &position_j, const std::vector<unsigned int> &component,
                              unsigned int n_components, const CorrectionExchange &exchange,
                              std::vector<double> &lambda, double tolerance = 1e-12, unsigned int max_iterations = 50000,
                              double coarse_size = 0, bool patch = false);
} // namespace shard::particles
