// SPDX-License-Identifier: LGPL-2.1-or-later
/**
 * @file spg_kernel.h
 * @brief The two-pass kinematics and internal force of the direct displacement smoothing
 *        (SPG) formulation on CSR stencils, in local indices (formulation.md section 3).
 * @ingroup particles
 *
 * With A the RK interpolation at the particles (row J: Psi_K(X_J)) and G the gradients of the
 * smoothing functions at the integration points (row I: grad Psi~_J(X_I)):
 * - pass 1: u_J = sum_K A_JK d_K (physical displacement at every particle);
 * - pass 2: F_I = I + sum_J u_J (x) G_IJ;
 * - scatter 1: g_J = sum_I G_IJ^T (V_I P_I), i.e. g_Jk = sum_I V_I P_I,kl G_IJ,l;
 * - scatter 2: f_K = sum_J A_JK g_J.
 * The scatters are the exact transposes of the passes, so f = dW/dd for W = sum_I V_I W(F_I).
 * Each scatter runs as a gather over a transposed index, so it is race-free under threads.
 */
#pragma once

#include <vector>

namespace shard::particles
{
  /// A read-only view of a CSR matrix with @p width doubles per entry.
  struct CsrView
  {
    /// Number of rows.
    unsigned int n_rows = 0;
    /// Row offsets, n_rows + 1 entries.
    const unsigned int *offsets = nullptr;
    /// Column of each entry.
    const unsigned int *columns = nullptr;
    /// Values, width per entry.
    const double *values = nullptr;
    /// Doubles per entry (1 for Psi, 3 for a gradient).
    unsigned int width = 1;
  };

  /**
   * @brief Two-pass SPG evaluation on fixed stencils (total-Lagrangian: built once).
   */
  class SpgKernel
  {
  public:
    /**
     * @brief Stores the stencils and builds the transposed indices.
     * @param interpolation A, width 1: rows are particles J, columns coefficients K
     * @param smoothing_gradient G, width 3: rows are integration points I, columns particles J
     * @param n_coefficients number of coefficients K (columns of A)
     */
    void
    reinit(const CsrView &interpolation, const CsrView &smoothing_gradient, unsigned int n_coefficients);

    /// Pass 1: u (3 per particle J) from the coefficients d (3 per K).
    void
    interpolate(const double *d, double *u) const;

    /// Pass 2: F (9 per integration point I, row-major F_ij) from u.
    void
    deformation_gradient(const double *u, double *F) const;

    /**
     * @brief Scatters 1 and 2 as gathers: f_K = sum_J A_JK sum_I V_I P_I G_IJ.
     * @param VP volume times first Piola-Kirchhoff stress, 9 per integration point (row-major)
     * @param[out] f internal force, 3 per coefficient; overwritten. The force acting on the
     *             coefficients is -f.
     */
    void
    internal_force(const double *VP, double *f) const;

    /**
     * @brief Scatter 1 alone: g_J = sum_I G_IJ^T (V P)_I, 3 per particle J (all n_particles()
     * rows are written).
     */
    void
    gradient_transpose(const double *VP, double *g) const;

    /**
     * @brief Scatter 2 alone, for @p width doubles per row: f_K = sum_J A_JK g_J, written for
     * every coefficient K (n_coefficients() entries of @p width).
     */
    void
    interpolate_transpose(const double *g, double *f, unsigned int width = 3) const;

    /// @name The passes over listed rows only (u rows J, F rows I, g rows J, f rows K), with
    /// exactly the sums of the full passes; for a refresh after rows of A or G changed in place.
    /// @{
    void
    interpolate(const double *d, double *u, const std::vector<unsigned int> &rows) const;
    void
    deformation_gradient(const double *u, double *F, const std::vector<unsigned int> &rows) const;
    void
    gradient_transpose(const double *VP, double *g, const std::vector<unsigned int> &rows) const;
    void
    interpolate_transpose(const double *g, double *f, const std::vector<unsigned int> &rows, unsigned int width) const;
    /// @}

    /**
     * @brief Copies the values of A and G into the order of the transposed indices, so that
     * the gathers of scatters 1 and 2 (run at two or more threads) stream through them instead
     * of reaching every value through the index. The gathers compute the same terms in the same
     * order as without the copies (bitwise the same results). Called by reinit() when more
     * than one thread runs; call it again after values of A or G changed in place: without
     * arguments for all rows, or with the rows that changed (@p a_rows of A, @p g_rows of G).
     * Does nothing at one thread (the push of scatters 1 and 2 streams through A and G).
     */
    void
    copy_transposed_values();
    void
    copy_transposed_values(const std::vector<unsigned int> &a_rows, const std::vector<unsigned int> &g_rows);

    /// Bytes of the transposed indices, the value copies and the scratch.
    std::size_t
    memory_consumption() const;

    /// Columns K of the rows @p rows of A (sorted, no duplicates).
    std::vector<unsigned int>
    interpolation_columns(const std::vector<unsigned int> &rows) const;

    /// Columns J of the rows @p rows of G (sorted, no duplicates).
    std::vector<unsigned int>
    gradient_columns(const std::vector<unsigned int> &rows) const;

    /// Rows I of G that hold one of the columns @p columns (sorted, no duplicates).
    std::vector<unsigned int>
    gradient_rows_using(const std::vector<unsigned int> &columns) const;

    /// g_J of the last internal_force() (3 per row J); a refresh updates it in place.
    std::vector<double> &
    last_gradient_transpose() const
    {
      return g_scratch_;
    }

    /// Number of coefficients K (columns of A).
    unsigned int
    n_coefficients() const
    {
      return n_coefficients_;
    }

    /// The interpolation stencil A.
    const CsrView &
    interpolation() const
    {
      return a_;
    }

    /// The smoothing-gradient stencil G.
    const CsrView &
    smoothing_gradient() const
    {
      return g_;
    }

    /// Number of particles J (rows of A).
    unsigned int
    n_particles() const
    {
      return a_.n_rows;
    }

    /// Number of integration points I (rows of G).
    unsigned int
    n_points() const
    {
      return g_.n_rows;
    }

  private:
    void
    interpolate_row(const double *d, double *u, unsigned int j) const;
    void
    deformation_gradient_row(const double *u, double *F, unsigned int i) const;
    void
    gradient_transpose_row(const double *VP, double *g, unsigned int j) const;
    void
    interpolate_transpose_row(const double *g, double *f, unsigned int k, unsigned int width) const;

    CsrView a_, g_;
    unsigned int n_coefficients_ = 0;
    // Transposed indices: for column c, the entries (row, entry index) that reference it.
    std::vector<unsigned int> at_offsets_, at_rows_, at_entries_;
    std::vector<unsigned int> gt_offsets_, gt_rows_, gt_entries_;
    // With more than one thread: the values in transposed order (1 per A entry, 3 per G entry)
    // and the slot of each forward entry in it (for the update of changed rows).
    std::vector<double>       at_values_, gt_values_;
    std::vector<unsigned int> at_slot_, gt_slot_;
    // Scratch of scatter 1.
    mutable std::vector<double> g_scratch_;
    // Scratch marks of the index-set queries.
    mutable std::vector<unsigned char> mark_;
  };
} // namespace shard::particles
