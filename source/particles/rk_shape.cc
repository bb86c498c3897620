// SPDX-License-Identifier: LGPL-2.1-or-later
// Reproducing-kernel shape functions: see include/shard/particles/rk_shape.h and
// doc/theory/rk_shape_functions.md.
#include <shard/particles/rk_shape.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <sstream>
#include <stdexcept>

namespace shard::particles
{
  namespace
  {
    /// phi'(z)/z for 0 <= z, finite at z = 0 (sphere gradient without 0/0).
    double
    dphi_over_z(const double z)
    {
      if (z <= 0.5)
        return -8.0 + 12.0 * z;
      if (z <= 1.0)
        return -4.0 * (1.0 - z) * (1.0 - z) / z;
      return 0.0;
    }

    /// Eigenvalues of a symmetric 4x4 matrix by cyclic Jacobi rotations (A is overwritten).
    void
    jacobi_eigenvalues(double (&A)[4][4], double (&lambda)[4])
    {
      double diag2 = 0.0;
      for (unsigned int p = 0; p < 4; ++p)
        diag2 += A[p][p] * A[p][p];
      for (unsigned int sweep = 0; sweep < 50; ++sweep)
        {
          double off2 = 0.0;
          for (unsigned int p = 0; p < 4; ++p)
            for (unsigned int q = p + 1; q < 4; ++q)
              off2 += A[p][q] * A[p][q];
          if (off2 <= 1e-32 * diag2 || off2 == 0.0)
            break;
          for (unsigned int p = 0; p < 4; ++p)
            for (unsigned int q = p + 1; q < 4; ++q)
              {
                const double apq = A[p][q];
                if (apq == 0.0)
                  continue;
                const double theta = (A[q][q] - A[p][p]) / (2.0 * apq);
                double       t;
                if (std::abs(theta) > 1e150)
                  t = 0.5 / theta;
                else
                  t = (theta >= 0.0 ? 1.0 : -1.0) / (std::abs(theta) + std::sqrt(theta * theta + 1.0));
                const double c = 1.0 / std::sqrt(t * t + 1.0);
                const double s = t * c;
                A[p][p] -= t * apq;
                A[q][q] += t * apq;
                A[p][q] = A[q][p] = 0.0;
                for (unsigned int k = 0; k < 4; ++k)
                  if (k != p && k != q)
                    {
                      const double akp = A[k][p];
                      const double akq = A[k][q];
                      A[k][p] = A[p][k] = c * akp - s * akq;
                      A[k][q] = A[q][k] = s * akp + c * akq;
                    }
              }
        }
      for (unsigned int p = 0; p < 4; ++p)
        lambda[p] = A[p][p];
    }

    /// Reciprocal 2-norm condition number lambda_min / lambda_max of a symmetric PSD 4x4 matrix.
    double
    reciprocal_condition(const double (&M)[4][4])
    {
      double A[4][4];
      for (unsigned int p = 0; p < 4; ++p)
        for (unsigned int q = 0; q < 4; ++q)
          A[p][q] = M[p][q];
      double lambda[4];
      jacobi_eigenvalues(A, lambda);
      const double lmax = std::max(std::max(lambda[0], lambda[1]), std::max(lambda[2], lambda[3]));
      const double lmin = std::min(std::min(lambda[0], lambda[1]), std::min(lambda[2], lambda[3]));
      if (!(lmax > 0.0) || !std::isfinite(lmax))
        return 0.0;
      return std::max(lmin, 0.0) / lmax;
    }

    /// LDL^T factorisation of a symmetric 4x4 matrix; false when a pivot is not clearly positive.
    bool
    ldlt_factorize(const double (&A)[4][4], double (&L)[4][4], double (&D)[4])
    {
      double scale = 0.0;
      for (unsigned int j = 0; j < 4; ++j)
        scale = std::max(scale, std::abs(A[j][j]));
      for (unsigned int j = 0; j < 4; ++j)
        {
          double d = A[j][j];
          for (unsigned int k = 0; k < j; ++k)
            d -= L[j][k] * L[j][k] * D[k];
          if (!(d > 1e-14 * scale) || !std::isfinite(d))
            return false;
          D[j]    = d;
          L[j][j] = 1.0;
          for (unsigned int i = j + 1; i < 4; ++i)
            {
              double v = A[i][j];
              for (unsigned int k = 0; k < j; ++k)
                v -= L[i][k] * L[j][k] * D[k];
              L[i][j] = v / d;
            }
        }
      return true;
    }

    /// Solves L D L^T x = b in place.
    void
    ldlt_solve(const double (&L)[4][4], const double (&D)[4], double (&x)[4])
    {
      for (unsigned int i = 1; i < 4; ++i)
        for (unsigned int k = 0; k < i; ++k)
          x[i] -= L[i][k] * x[k];
      for (unsigned int i = 0; i < 4; ++i)
        x[i] /= D[i];
      for (int i = 2; i >= 0; --i)
        for (unsigned int k = i + 1; k < 4; ++k)
          x[i] -= L[k][i] * x[k];
    }

    void
    throw_invalid(const std::string &what)
    {
      throw std::invalid_argument("build_rk_stencil: " + what);
    }

    /// Checks the input of build_rk_stencil(). @throws std::invalid_argument
    void
    check_stencil_input(const std::vector<Point3> &eval_points, const std::vector<Point3> &particle_positions,
                        const std::vector<Point3> &support_radii, const CsrPattern &neighbors)
    {
      const std::size_t n_particles = particle_positions.size();
      if (n_particles > std::numeric_limits<unsigned int>::max())
        throw_invalid("too many particles for unsigned int indices");
      if (support_radii.size() != n_particles)
        throw_invalid("support_radii must have one entry per particle");
      for (const Point3 &a : support_radii)
        for (unsigned int k = 0; k < 3; ++k)
          if (!(a[k] > 0.0) || !std::isfinite(a[k]))
            throw_invalid("support radii must be positive and finite");
      if (neighbors.row_offsets.size() != eval_points.size() + 1)
        throw_invalid("neighbors must have one row per evaluation point");
      if (neighbors.row_offsets.front() != 0 || neighbors.row_offsets.back() != neighbors.columns.size())
        throw_invalid("neighbors.row_offsets must start at 0 and end at columns.size()");
      for (std::size_t r = 0; r < eval_points.size(); ++r)
        if (neighbors.row_offsets[r + 1] < neighbors.row_offsets[r])
          throw_invalid("neighbors.row_offsets must not decrease");
      for (const unsigned int c : neighbors.columns)
        if (c >= n_particles)
          throw_invalid("neighbor index out of range");
    }

    /// One row of a stencil under construction: evaluation point X, entries [begin, end) of
    /// columns, psi and (times 3) grad.
    struct StencilRow
    {
      const Point3       &X;
      const unsigned int  begin, end;
      const unsigned int *columns;
      double             *psi, *grad;
    };

    /// Pass 1 over a row: what the kernel sums tell.
    struct KernelSums
    {
      /// Entries with a positive weight.
      unsigned int n_weighted = 0;
      /// Scaling lengths: the largest support radius per direction of the weighted entries.
      double s[3] = {0.0, 0.0, 0.0};
      /// Sum of the kernel values and of their gradients.
      double sum_phi = 0.0, sum_dphi[3] = {0.0, 0.0, 0.0};
    };

    /// Pass 1: kernel values and gradients (stored in place in psi and grad), scaling lengths.
    KernelSums
    kernel_pass(const StencilRow &row, const std::vector<Point3> &particle_positions,
                const std::vector<Point3> &support_radii, const Support support)
    {
      KernelSums out;
      for (unsigned int e = row.begin; e < row.end; ++e)
        {
          const unsigned int I  = row.columns[e];
          const Point3      &XI = particle_positions[I];
          const Point3      &aI = support_radii[I];
          const Point3       r  = {{row.X[0] - XI[0], row.X[1] - XI[1], row.X[2] - XI[2]}};
          Point3             g;
          const double       w = kernel_value_and_gradient(r, aI, support, g);
          row.psi[e]           = w;
          for (unsigned int k = 0; k < 3; ++k)
            row.grad[3 * e + k] = g[k];
          if (w > 0.0)
            {
              ++out.n_weighted;
              for (unsigned int k = 0; k < 3; ++k)
                out.s[k] = std::max(out.s[k], aI[k]);
            }
          out.sum_phi += w;
          for (unsigned int k = 0; k < 3; ++k)
            out.sum_dphi[k] += g[k];
        }
      return out;
    }

    /// Pass 2: the moment matrix M of the basis H = [1, (X - X_I)/s] and its derivatives M_,k.
    void
    moment_pass(const StencilRow &row, const std::vector<Point3> &particle_positions, const double (&s)[3],
                double (&M)[4][4], double (&dM)[3][4][4])
    {
      const Point3 &X = row.X;
      // The H H^T Phi_,k part of the derivatives (upper triangles).
      for (unsigned int e = row.begin; e < row.end; ++e)
        {
          const double w = row.psi[e];
          if (w == 0.0)
            continue;
          const Point3 &XI   = particle_positions[row.columns[e]];
          const double  H[4] = {1.0, (X[0] - XI[0]) / s[0], (X[1] - XI[1]) / s[1], (X[2] - XI[2]) / s[2]};
          const double *g    = row.grad + 3 * e;
          for (unsigned int p = 0; p < 4; ++p)
            for (unsigned int q = p; q < 4; ++q)
              {
                const double hh = H[p] * H[q];
                M[p][q] += hh * w;
                dM[0][p][q] += hh * g[0];
                dM[1][p][q] += hh * g[1];
                dM[2][p][q] += hh * g[2];
              }
        }
      for (unsigned int p = 0; p < 4; ++p)
        for (unsigned int q = 0; q < p; ++q)
          {
            M[p][q] = M[q][p];
            for (unsigned int k = 0; k < 3; ++k)
              dM[k][p][q] = dM[k][q][p];
          }
      // sum_I (e_{k+1} H^T + H e_{k+1}^T) Phi / s_k = (e_{k+1} m^T + m e_{k+1}^T) / s_k, m = M e_0
      for (unsigned int k = 0; k < 3; ++k)
        for (unsigned int p = 0; p < 4; ++p)
          {
            dM[k][k + 1][p] += M[p][0] / s[k];
            dM[k][p][k + 1] += M[p][0] / s[k];
          }
    }

    /// Shepard functions of a row: Psi = Phi / S, grad Psi = grad Phi / S - Phi grad S / S^2.
    void
    shepard_row(const StencilRow &row, const KernelSums &sums)
    {
      const double invS = 1.0 / sums.sum_phi;
      for (unsigned int e = row.begin; e < row.end; ++e)
        {
          const double w = row.psi[e];
          row.psi[e]     = w * invS;
          for (unsigned int k = 0; k < 3; ++k)
            row.grad[3 * e + k] = (row.grad[3 * e + k] - w * invS * sums.sum_dphi[k]) * invS;
        }
    }

    /// The RK functions of a row from the factor L D L^T of M: b_0 = M^{-1} H(0),
    /// b_k = -M^{-1} M_,k b_0, then pass 3: Psi_I = Phi b0.H,
    /// Psi_I,k = Phi b_k.H + Phi b0_{k+1} / s_k + Phi_,k b0.H.
    void
    rk_row(const StencilRow &row, const std::vector<Point3> &particle_positions, const double (&s)[3],
           const double (&L)[4][4], const double (&D)[4], const double (&dM)[3][4][4])
    {
      double b0[4] = {1.0, 0.0, 0.0, 0.0};
      ldlt_solve(L, D, b0);
      double b[3][4];
      for (unsigned int k = 0; k < 3; ++k)
        {
          for (unsigned int p = 0; p < 4; ++p)
            {
              double v = 0.0;
              for (unsigned int q = 0; q < 4; ++q)
                v += dM[k][p][q] * b0[q];
              b[k][p] = -v;
            }
          ldlt_solve(L, D, b[k]);
        }

      const Point3 &X = row.X;
      for (unsigned int e = row.begin; e < row.end; ++e)
        {
          const double w = row.psi[e];
          if (w == 0.0)
            continue;
          const Point3 &XI   = particle_positions[row.columns[e]];
          const double  H[4] = {1.0, (X[0] - XI[0]) / s[0], (X[1] - XI[1]) / s[1], (X[2] - XI[2]) / s[2]};
          const double  hb0  = b0[0] + H[1] * b0[1] + H[2] * b0[2] + H[3] * b0[3];
          row.psi[e]         = w * hb0;
          for (unsigned int k = 0; k < 3; ++k)
            {
              const double hbk    = b[k][0] + H[1] * b[k][1] + H[2] * b[k][2] + H[3] * b[k][3];
              row.grad[3 * e + k] = w * hbk + w * b0[k + 1] / s[k] + row.grad[3 * e + k] * hb0;
            }
        }
    }
  } // namespace


  double
  phi(double z)
  {
    z = std::abs(z);
    if (z <= 0.5)
      return 2.0 / 3.0 - 4.0 * z * z + 4.0 * z * z * z;
    if (z <= 1.0)
      {
        const double w = 1.0 - z;
        return 4.0 / 3.0 * w * w * w;
      }
    return 0.0;
  }


  double
  dphi(const double z)
  {
    const double x = std::abs(z);
    double       d = 0.0;
    if (x <= 0.5)
      d = -8.0 * x + 12.0 * x * x;
    else if (x <= 1.0)
      d = -4.0 * (1.0 - x) * (1.0 - x);
    return z < 0.0 ? -d : d;
  }


  double
  kernel_value(const Point3 &r, const Point3 &a, const Support support)
  {
    if (support == Support::box)
      return phi(r[0] / a[0]) * phi(r[1] / a[1]) * phi(r[2] / a[2]);
    const double z0 = r[0] / a[0], z1 = r[1] / a[1], z2 = r[2] / a[2];
    return phi(std::sqrt(z0 * z0 + z1 * z1 + z2 * z2));
  }


  double
  kernel_value_and_gradient(const Point3 &r, const Point3 &a, const Support support, Point3 &gradient)
  {
    const double z[3] = {r[0] / a[0], r[1] / a[1], r[2] / a[2]};
    if (support == Support::box)
      {
        const double f[3] = {phi(z[0]), phi(z[1]), phi(z[2])};
        gradient[0]       = dphi(z[0]) / a[0] * f[1] * f[2];
        gradient[1]       = f[0] * dphi(z[1]) / a[1] * f[2];
        gradient[2]       = f[0] * f[1] * dphi(z[2]) / a[2];
        return f[0] * f[1] * f[2];
      }
    const double zz = std::sqrt(z[0] * z[0] + z[1] * z[1] + z[2] * z[2]);
    // d phi(zz)/dX_k = phi'(zz) z_k / (a_k zz)
    const double g = dphi_over_z(zz);
    for (unsigned int k = 0; k < 3; ++k)
      gradient[k] = g * z[k] / a[k];
    return phi(zz);
  }


  void
  RkParameters::check() const
  {
    if (!(dilation >= 1.0) || !std::isfinite(dilation))
      {
        std::ostringstream s;
        s << "dilation = " << dilation
          << " must be >= 1 (LS-DYNA forbids values below 1.0; 1.4-1.8 advised)";
        throw std::invalid_argument(s.str());
      }
    if (!(rcond_limit >= 0.0 && rcond_limit < 1.0))
      {
        std::ostringstream s;
        s << "rcond_limit = " << rcond_limit << " must lie in [0, 1)";
        throw std::invalid_argument(s.str());
      }
  }


  std::string
  RkParameters::warning() const
  {
    if (dilation < 1.4 || dilation > 1.8)
      {
        std::ostringstream s;
        s << "dilation = " << dilation
          << " lies outside the advised range 1.4-1.8 (larger values cost more and can make the solution diverge)";
        return s.str();
      }
    return {};
  }


  std::vector<Point3>
  support_radii_from_spacing(const std::vector<Point3> &spacing, const RkParameters &params)
  {
    params.check();
    std::vector<Point3> a(spacing.size());
    for (std::size_t i = 0; i < spacing.size(); ++i)
      {
        for (unsigned int k = 0; k < 3; ++k)
          if (!(spacing[i][k] > 0.0) || !std::isfinite(spacing[i][k]))
            throw std::invalid_argument("support_radii_from_spacing: spacing must be positive and finite");
        a[i] = params.support_radius(spacing[i]);
      }
    return a;
  }


  TransposedIndex
  build_transposed_index(const Stencil &stencil)
  {
    const unsigned int n_rows    = stencil.n_rows();
    const unsigned int n_columns = stencil.n_columns;
    const std::size_t  n_entries = stencil.columns.size();

    TransposedIndex t;
    t.column_offsets.assign(std::size_t(n_columns) + 1, 0u);
    for (const unsigned int c : stencil.columns)
      {
        if (c >= n_columns)
          throw std::invalid_argument("build_transposed_index: column index out of range");
        ++t.column_offsets[c + 1];
      }
    for (unsigned int c = 0; c < n_columns; ++c)
      t.column_offsets[c + 1] += t.column_offsets[c];

    t.rows.resize(n_entries);
    t.entries.resize(n_entries);
    std::vector<unsigned int> next(t.column_offsets.begin(), t.column_offsets.end() - 1);
    // Rows in ascending order, so every column lists its rows ascending.
    for (unsigned int r = 0; r < n_rows; ++r)
      for (unsigned int e = stencil.row_offsets[r]; e < stencil.row_offsets[r + 1]; ++e)
        {
          const unsigned int slot = next[stencil.columns[e]]++;
          t.rows[slot]            = r;
          t.entries[slot]         = e;
        }
    return t;
  }


  Stencil
  build_rk_stencil(const std::vector<Point3> &eval_points,
                   const std::vector<Point3> &particle_positions,
                   const std::vector<Point3> &support_radii,
                   const CsrPattern          &neighbors,
                   const RkParameters        &params)
  {
    params.check();
    check_stencil_input(eval_points, particle_positions, support_radii, neighbors);

    const Support support = params.support;
    const double  limit   = params.rcond_limit;

    Stencil st;
    st.n_columns   = static_cast<unsigned int>(particle_positions.size());
    st.row_offsets = neighbors.row_offsets;
    st.columns     = neighbors.columns;
    st.psi.assign(st.columns.size(), 0.0);
    st.grad.assign(3 * st.columns.size(), 0.0);
    st.fallback.assign(eval_points.size(), 0);
    st.rcond.assign(eval_points.size(), 0.0);

    for (std::size_t r = 0; r < eval_points.size(); ++r)
      {
        const StencilRow row{eval_points[r], st.row_offsets[r], st.row_offsets[r + 1], st.columns.data(),
                             st.psi.data(), st.grad.data()};
        const KernelSums sums = kernel_pass(row, particle_positions, support_radii, support);
        if (sums.n_weighted == 0)
          {
            // No neighbour left: a free point; all entries are zero already.
            st.fallback[r] = 1;
            st.rcond[r]    = 0.0;
            continue;
          }

        double M[4][4]     = {};
        double dM[3][4][4] = {};
        moment_pass(row, particle_positions, sums.s, M, dM);
        st.rcond[r] = reciprocal_condition(M);

        double     L[4][4] = {};
        double     D[4]    = {};
        const bool use_rk  = sums.n_weighted >= 4 && st.rcond[r] >= limit && ldlt_factorize(M, L, D);
        if (use_rk)
          rk_row(row, particle_positions, sums.s, L, D, dM);
        else
          {
            st.fallback[r] = 1;
            shepard_row(row, sums);
          }
      }
    return st;
  }
  bool
  invert_spd4(const double *matrix, double *inverse)
  {
    double A[4][4], L[4][4] = {}, D[4];
    for (unsigned int r = 0; r < 4; ++r)
      for (unsigned int c = 0; c < 4; ++c)
        A[r][c] = matrix[4 * r + c];
    if (!ldlt_factorize(A, L, D))
      return false;
    for (unsigned int c = 0; c < 4; ++c)
      {
        double x[4] = {0, 0, 0, 0};
        x[c]        = 1;
        ldlt_solve(L, D, x);
        for (unsigned int r = 0; r < 4; ++r)
          inverse[4 * r + c] = x[r];
      }
    return true;
  }
} // namespace shard::particles
