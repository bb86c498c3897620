// SPDX-License-Identifier: LGPL-2.1-or-later
/**
 * @file spg_operator.h
 * @brief The particle formulation on local compact arrays: local stencils from a particle
 *        cloud, the two-level (or single-level DNI) kinematics, the internal force with the
 *        variationally consistent gradient correction, the residual stabilization and the
 *        displacement smoothing filter (formulation.md section 3; doc/theory/spg_stabilization.md).
 * @ingroup particles
 *
 * Index spaces (all local to one rank):
 * - K, the coefficients: every particle whose coefficient d_K enters a local row, 0..n_k;
 * - J, the particles at which the physical displacement u_J = sum_K A_JK d_K is evaluated:
 *   the first n_j coefficients (J and K share their numbering below n_j);
 * - I, the integration points: the owned particles, the first n_i coefficients.
 * A has n_j rows and n_k columns, G (grad Psi~ at X_I) n_i rows and n_j columns. Products
 * over the owned rows are partial sums across ranks; the caller adds them up (compress).
 *
 * Nothing here depends on deal.II: the same code runs in the solver and in the unit tests
 * (spectral, patch and energy tests assemble stiffness matrices through it).
 */
#pragma once

#include <shard/particles/local_stencils.h>
#include <shard/particles/rk_shape.h>
#include <shard/particles/spg_kernel.h>

#include <functional>
#include <vector>

namespace shard::particles
{
  /// How the nodal deformation gradient is formed.
  enum class Smoothing
  {
    /// Direct nodal integration of the RK functions: u_J = d_J, F_I = I + sum_J d_J (x) grad Psi_J(X_I).
    none,
    /// Two-level smoothed functions: u = A d, F_I = I + sum_J u_J (x) grad Psi~_J(X_I).
    two_level
  };

  /// Remedy against zero-energy (odd-even) modes, formulation.md section 3.
  enum class Stabilization
  {
    /// R0: none.
    none,
    /// R1: every N steps the coefficients and their velocities are replaced by A d, A v.
    filter,
    /// R2: residual force f = -alpha (I - A)^T Lambda (I - A) d.
    residual
  };

  /// Correction of the nodal gradients so that nodal integration meets the integration
  /// constraint (Galerkin patch test; doc/theory/spg_stabilization.md).
  enum class Correction
  {
    /// None: the seed form, for comparison.
    none,
    /// Petrov-Galerkin: test-function gradients grad phi_K + xi_K Psi_K (non-symmetric
    /// stiffness with complex eigenvalues on free surfaces; grows in dynamics).
    petrov_galerkin,
    /// Consistent (default): the smallest symmetric change of the nodal gradients G that keeps
    /// linear exactness and meets the constraint (ConsistentCorrection).
    consistent
  };

  /// Options of the formulation (subsection `F - Particle formulation`).
  struct FormulationOptions
  {
    Smoothing     smoothing           = Smoothing::two_level;
    Stabilization stabilization       = Stabilization::residual;
    /// alpha of R2 (unit 1).
    double residual_coefficient = 0.1;
    /// N of R1 (steps).
    unsigned int filter_interval = 15;
    /// Correction of the nodal gradients for the integration constraint.
    Correction correction = Correction::consistent;
  };

  /**
   * @brief The particle operators of one rank on compact arrays (3 doubles per particle for
   * vectors, 9 row-major for tensors).
   */
  class SpgOperator
  {
  public:
    /**
     * @brief Stores the stencils (which must outlive this object) and the options. Stencil
     * values are read through views at every evaluation, so gradients replaced in place (the
     * consistent correction) take effect without a new reinit().
     * @param lambda residual weights Lambda_I = V_I M_I / a_I^2 of the owned rows (M the
     *        P-wave modulus, a the support radius), used by R2
     */
    void
    reinit(const LocalStencils &stencils, const FormulationOptions &options, const std::vector<double> &lambda);

    /// Pass 1: u over the n_j rows (3 each) from d over the n_k coefficients.
    void
    displacement(const double *d, double *u) const;

    /// Pass 2: F (9 per owned row) from u.
    void
    deformation_gradient(const double *u, double *F) const;

    /**
     * @brief Subtracts the internal force A^T G^T (V P) (plus the gradient correction when
     * set) from @p f (3 per coefficient K).
     * @param VP V_I P_I per owned row, 9 each (first Piola-Kirchhoff, row-major)
     */
    void
    subtract_internal_force(const double *VP, double *f) const;

    /**
     * @brief R2: subtracts alpha (I - A)^T Lambda ((I - A) d - r0) from @p f: the gradient of
     * W_s = (alpha / 2) sum_I Lambda_I |d_I - (A d)_I - r0_I|^2 over the owned rows (r0 the
     * offsets of rows rebuilt during the run, rebase_residual(); zero otherwise).
     *
     * The residual acts on the coefficients, not on u = A d: at large dilations A is nearly
     * singular and its near-null vectors (the odd-even family) have u close to zero, so a
     * residual of u cannot see them (doc/theory/spg_stabilization.md).
     * @param d coefficients over the n_k columns
     * @return the stabilization energy W_s of the owned rows
     */
    double
    subtract_residual_force(const double *d, double *f) const;

    /**
     * @brief Rebases the residual of the owned rows @p rows: their offset r0_I is set so that
     * the residual d_I - (A d)_I - r0_I at the coefficients @p d (3 per K) equals @p target
     * (3 per row, in the order of @p rows; nullptr: the residual of the last evaluation,
     * last_residual()). Call after rows of A changed (bonds broke, a conversion rebuilt the
     * stencils): the stabilization energy W_s then does not jump at the rebuild. Without it,
     * a row rebuilt from few or one-sided bonds in a deformed zone has a residual of the order
     * of h |grad u| at once, and W_s grew by 1.7 kJ in three steps of the showcase.
     */
    void
    rebase_residual(const double *d, const std::vector<unsigned int> &rows, const double *target = nullptr);

    /// Residual d_I - (A d)_I - r0_I of owned row @p i at the last evaluation (3 values; zero
    /// before the first or without the residual stabilization).
    const double *
    last_residual(const unsigned int i) const
    {
      static const double zero[3] = {0, 0, 0};
      return 3 * i < last_residual_.size() ? &last_residual_[3 * i] : zero;
    }

    /// Offset r0_I of owned row @p i (3 values; zero unless rebased).
    const double *
    residual_offset(const unsigned int i) const
    {
      static const double zero[3] = {0, 0, 0};
      return 3 * i < residual_offset_.size() ? &residual_offset_[3 * i] : zero;
    }

    /// Sets the offset r0_I of owned row @p i (restart).
    void
    set_residual_offset(unsigned int i, const double *r0);

    /**
     * @brief Partial sums (owned rows only) of the integration-constraint terms of every
     * coefficient K: @p c = sum_I V_I grad phi_K(X_I) (3 per K), @p b = sum_J a_J A_JK
     * (the nodal boundary integral of phi_K n, 3 per K) and @p w = sum_I V_I A_IK (1 per K).
     * @param volume V_I of the owned rows
     * @param area_vector outward area vector a_J of the owned rows (zero inside the body)
     */
    void
    integration_terms(const double *volume, const double *area_vector, double *c, double *b, double *w) const;

    /**
     * @brief Refreshes the value copies of the gathers (SpgKernel::copy_transposed_values) of
     * both kernels: all rows, or the rows @p a_rows of A and @p g_rows of G that changed in
     * place. Call before the next evaluation after the stencil values changed.
     */
    void
    copy_transposed_values();
    void
    copy_transposed_values(const std::vector<unsigned int> &a_rows, const std::vector<unsigned int> &g_rows);

    /**
     * @brief After the rows @p a_rows of A and @p g_rows of G changed in place (bonds broke),
     * recomputes only what depends on them: u of the changed A rows, F of the points that read
     * a changed row, their V P (through @p update_vp), the g of the particles those points
     * reach, and the force of every coefficient whose sum changed. The result equals
     * subtract_internal_force() plus subtract_residual_force() on the new rows to the last bit.
     * Valid only right after those two ran (at the same @p d) on the old rows: it reuses their
     * g and residual weights.
     * @param d the coefficients of that evaluation (3 per K)
     * @param u, F, VP the arrays of that evaluation, updated in place
     * @param update_vp recomputes VP of point i from F of point i
     * @param f the force of that evaluation (3 per K), updated in place
     * @param a_rows, g_rows the changed rows (sorted)
     * @param[out] changed the coefficients K whose force was recomputed (sorted)
     * @return the residual stabilization energy (0 without it)
     */
    double
    refresh_internal_force(const double *d, double *u, double *F, double *VP,
                           const std::function<void(unsigned int)> &update_vp, double *f,
                           const std::vector<unsigned int> &a_rows, const std::vector<unsigned int> &g_rows,
                           std::vector<unsigned int> &changed) const;

    /**
     * @brief Sets the gradient correction xi_K (3 per coefficient K), so that the test-function
     * gradients grad phi_K + xi_K Psi_K meet sum_I V_I grad phi_K(X_I) = sum_J a_J phi_K(X_J).
     */
    void
    set_gradient_correction(std::vector<double> xi);

    /// Applies R1 to the owned rows: out_I = (A in)_I for I < n_i (3 per row).
    void
    smooth_owned(const double *in, double *out) const;

    /// The options.
    const FormulationOptions &
    options() const
    {
      return options_;
    }

    /// Number of owned rows I.
    unsigned int
    n_i() const
    {
      return n_i_;
    }

    /// Number of rows J of A.
    unsigned int
    n_j() const
    {
      return n_j_;
    }

    /// Number of coefficients K.
    unsigned int
    n_k() const
    {
      return n_k_;
    }

    /**
     * @brief Bytes held by the operator: residual weights, gradient corrections (xi and the
     * replaced gradients), scratch and identity rows (allocated capacities), plus the transposed indices and scratch of its two
     * SpgKernel objects. The kernels' arrays are counted from the stencil sizes (SpgKernel
     * allocates n_columns + 1 offsets and two indices per entry for each of A and G, and 3
     * doubles per row of A). The stencil values themselves belong to LocalStencils and are
     * not counted here.
     */
    std::size_t
    memory_consumption() const;

  private:
    FormulationOptions        options_;
    unsigned int              n_i_ = 0, n_j_ = 0, n_k_ = 0;
    std::vector<unsigned int> identity_offsets_, identity_columns_;
    std::vector<double>       identity_values_;
    SpgKernel                 kernel_;     // A used for u (identity for DNI) and G
    SpgKernel                 smoothing_;  // RK A for the residual and the filter
    std::vector<double>       lambda_, xi_;
    mutable std::vector<double> scratch_j_, scratch_j9_, scratch_k_, scratch_k9_;
    /// Residual energy of each owned row at the last evaluation.
    mutable std::vector<double> residual_energy_;
    /// Offset r0_I of each owned row (3 per row; empty: all zero), see rebase_residual().
    std::vector<double> residual_offset_;
    /// Residual d_I - (A d)_I - r0_I of each owned row at the last evaluation (3 per row).
    mutable std::vector<double> last_residual_;
    /// d_i - (A d)_i of row @p i without the offset, into @p s (3 values).
    static void
    plain_residual(const CsrView &a, const double *d, unsigned int i, double *s);
    /// Residual of owned row i: weight into scratch_j_, energy into residual_energy_.
    void
    residual_row(const CsrView &a, const double *d, unsigned int i) const;
  };

} // namespace shard::particles
