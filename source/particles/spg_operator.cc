// SPDX-License-Identifier: LGPL-2.1-or-later
#include <shard/base/parallel.h>
#include <shard/particles/neighbor_build.h>
#include <shard/particles/spg_operator.h>

#include <Eigen/Dense>
#include <Eigen/CholmodSupport>

#include <algorithm>
#include <array>
#include <cstdint>
#include <iterator>
#include <map>
#include <memory>
#include <unordered_map>
#include <cmath>
#include <stdexcept>
#include <string>

namespace shard::particles
{
  namespace
  {
    /// Rows per task of the threaded passes (a fixed partition; each row is written by one task).
    constexpr unsigned int rows_per_task = 1024;

    CsrView
    view(const Stencil &s, const bool gradient)
    {
      return CsrView{s.n_rows(), s.row_offsets.data(), s.columns.data(),
                     gradient ? s.grad.data() : s.psi.data(), gradient ? 3u : 1u};
    }
  } // namespace

  void
  SpgOperator::reinit(const LocalStencils &stencils, const FormulationOptions &options,
                      const std::vector<double> &lambda)
  {
    options_  = options;
    n_i_      = stencils.n_i;
    n_j_      = stencils.n_j;
    n_k_      = stencils.n_k;
    if (options_.stabilization == Stabilization::residual && lambda.size() != n_i_)
      throw std::invalid_argument("SpgOperator: one residual weight per owned particle expected");
    lambda_ = lambda;
    xi_.clear();
    residual_offset_.clear();
    last_residual_.assign(3 * n_i_, 0.);
    const CsrView g = view(stencils.g, true);
    const CsrView a = view(stencils.a, false);
    smoothing_.reinit(a, g, n_k_);
    if (options_.smoothing == Smoothing::two_level)
      kernel_.reinit(a, g, n_k_);
    else
      {
        identity_offsets_.resize(n_j_ + 1);
        identity_columns_.resize(n_j_);
        identity_values_.assign(n_j_, 1.);
        for (unsigned int j = 0; j <= n_j_; ++j)
          identity_offsets_[j] = j;
        for (unsigned int j = 0; j < n_j_; ++j)
          identity_columns_[j] = j;
        kernel_.reinit(CsrView{n_j_, identity_offsets_.data(), identity_columns_.data(), identity_values_.data(), 1},
                       g, n_k_);
      }
    scratch_j_.assign(3 * n_j_, 0.);
    scratch_j9_.assign(9 * n_j_, 0.);
    scratch_k_.assign(3 * n_k_, 0.);
    scratch_k9_.assign(9 * n_k_, 0.);
  }

  void
  SpgOperator::displacement(const double *d, double *u) const
  {
    kernel_.interpolate(d, u);
  }

  void
  SpgOperator::deformation_gradient(const double *u, double *F) const
  {
    kernel_.deformation_gradient(u, F);
  }

  void
  SpgOperator::subtract_internal_force(const double *VP, double *f) const
  {
    kernel_.internal_force(VP, scratch_k_.data());
    base::for_each_range(n_k_, rows_per_task, [&](const unsigned int begin, const unsigned int end) {
      for (unsigned int k = 3 * begin; k < 3 * end; ++k)
        f[k] -= scratch_k_[k];
    });
    if (xi_.empty())
      return;
    // Correction sum_I V_I P_I xi_K Psi_K(X_I): one more transposed gather of V P with A.
    std::copy(VP, VP + 9 * n_i_, scratch_j9_.begin());
    kernel_.interpolate_transpose(scratch_j9_.data(), scratch_k9_.data(), 9);
    base::for_each_range(n_k_, rows_per_task, [&](const unsigned int begin, const unsigned int end) {
      for (unsigned int k = begin; k < end; ++k)
        {
          const double *q = &scratch_k9_[9 * k];
          const double *x = &xi_[3 * k];
          for (unsigned int i = 0; i < 3; ++i)
            f[3 * k + i] -= q[3 * i] * x[0] + q[3 * i + 1] * x[1] + q[3 * i + 2] * x[2];
        }
    });
  }

  double
  SpgOperator::subtract_residual_force(const double *d, double *f) const
  {
    const CsrView &a = smoothing_.interpolation();
    // w_I = Lambda_I (d_I - (A d)_I) on the owned rows, zero on the other rows J.
    double *w      = scratch_j_.data();
    residual_energy_.resize(n_i_);
    base::for_each_range(n_i_, rows_per_task, [&](const unsigned int begin, const unsigned int end) {
      for (unsigned int i = begin; i < end; ++i)
        residual_row(a, d, i);
    });
    // Summed in row order, whatever the thread count.
    double energy = 0;
    for (unsigned int i = 0; i < n_i_; ++i)
      energy += residual_energy_[i];
    std::fill(w + 3 * n_i_, w + 3 * n_j_, 0.);
    // f -= alpha (I - A)^T w.
    smoothing_.interpolate_transpose(w, scratch_k_.data(), 3);
    const double alpha = options_.residual_coefficient;
    base::for_each_range(n_k_, rows_per_task, [&](const unsigned int begin, const unsigned int end) {
      for (unsigned int k = 3 * begin; k < 3 * end; ++k)
        {
          if (k < 3 * n_i_)
            f[k] -= alpha * w[k];
          f[k] += alpha * scratch_k_[k];
        }
    });
    return energy;
  }

  void
  SpgOperator::residual_row(const CsrView &a, const double *d, const unsigned int i) const
  {
    double s[3];
    plain_residual(a, d, i, s);
    if (!residual_offset_.empty())
      for (unsigned int c = 0; c < 3; ++c)
        s[c] -= residual_offset_[3 * i + c];
    double energy = 0;
    for (unsigned int c = 0; c < 3; ++c)
      {
        energy += 0.5 * options_.residual_coefficient * lambda_[i] * s[c] * s[c];
        scratch_j_[3 * i + c]     = lambda_[i] * s[c];
        last_residual_[3 * i + c] = s[c];
      }
    residual_energy_[i] = energy;
  }

  void
  SpgOperator::plain_residual(const CsrView &a, const double *d, const unsigned int i, double *s)
  {
    for (unsigned int c = 0; c < 3; ++c)
      s[c] = d[3 * i + c];
    for (unsigned int e = a.offsets[i]; e < a.offsets[i + 1]; ++e)
      for (unsigned int c = 0; c < 3; ++c)
        s[c] -= a.values[e] * d[3 * a.columns[e] + c];
  }

  void
  SpgOperator::rebase_residual(const double *d, const std::vector<unsigned int> &rows, const double *target)
  {
    if (options_.stabilization != Stabilization::residual || rows.empty())
      return;
    if (residual_offset_.empty())
      residual_offset_.assign(3 * n_i_, 0.);
    last_residual_.resize(3 * n_i_, 0.);
    const CsrView &a = smoothing_.interpolation();
    for (std::size_t r = 0; r < rows.size(); ++r)
      {
        const unsigned int i = rows[r];
        double             s[3];
        plain_residual(a, d, i, s);
        const double *t = target ? target + 3 * r : &last_residual_[3 * i];
        for (unsigned int c = 0; c < 3; ++c)
          residual_offset_[3 * i + c] = s[c] - t[c];
      }
  }

  void
  SpgOperator::set_residual_offset(const unsigned int i, const double *r0)
  {
    if (residual_offset_.empty())
      {
        if (r0[0] == 0 && r0[1] == 0 && r0[2] == 0)
          return;
        residual_offset_.assign(3 * n_i_, 0.);
      }
    std::copy(r0, r0 + 3, &residual_offset_[3 * i]);
  }

  void
  SpgOperator::copy_transposed_values()
  {
    kernel_.copy_transposed_values();
    smoothing_.copy_transposed_values();
  }

  void
  SpgOperator::copy_transposed_values(const std::vector<unsigned int> &a_rows, const std::vector<unsigned int> &g_rows)
  {
    kernel_.copy_transposed_values(a_rows, g_rows);
    smoothing_.copy_transposed_values(a_rows, g_rows);
  }

  double
  SpgOperator::refresh_internal_force(const double *d, double *u, double *F, double *VP,
                                      const std::function<void(unsigned int)> &update_vp, double *f,
                                      const std::vector<unsigned int> &a_rows, const std::vector<unsigned int> &g_rows,
                                      std::vector<unsigned int> &changed) const
  {
    // Union of two sorted index lists.
    const auto merged = [](const std::vector<unsigned int> &x, const std::vector<unsigned int> &y) {
      std::vector<unsigned int> out;
      out.reserve(x.size() + y.size());
      std::set_union(x.begin(), x.end(), y.begin(), y.end(), std::back_inserter(out));
      return out;
    };
    // The u rows of A that changed (for DNI kernel_'s A is the identity: u does not change), then
    // the points whose F changes: new G rows, or G rows that read a changed u.
    kernel_.interpolate(d, u, a_rows);
    const auto points = merged(g_rows, kernel_.gradient_rows_using(a_rows));
    kernel_.deformation_gradient(u, F, points);
    for (const unsigned int i : points)
      update_vp(i);
    // g_J = sum_I G_IJ^T (V P)_I of every J those points reach.
    auto      &g       = kernel_.last_gradient_transpose();
    const auto reached = kernel_.gradient_columns(points);
    kernel_.gradient_transpose(VP, g.data(), reached);
    // The coefficients whose force changes: columns of the A rows with a new g or new values,
    // of the A rows of the points (correction xi), and of the changed residual rows.
    std::vector<unsigned int> owned_a;
    for (const unsigned int r : a_rows)
      if (r < n_i_)
        owned_a.push_back(r);
    changed = kernel_.interpolation_columns(merged(reached, a_rows));
    if (!xi_.empty())
      changed = merged(changed, kernel_.interpolation_columns(merged(points, owned_a)));
    const bool residual = options_.stabilization == Stabilization::residual;
    if (residual)
      changed = merged(merged(changed, smoothing_.interpolation_columns(owned_a)), owned_a);
    // Their forces, with the sums of subtract_internal_force and subtract_residual_force.
    kernel_.interpolate_transpose(g.data(), scratch_k_.data(), changed, 3);
    for (const unsigned int k : changed)
      for (unsigned int c = 0; c < 3; ++c)
        f[3 * k + c] = 0. - scratch_k_[3 * k + c];
    if (!xi_.empty())
      {
        std::copy(VP, VP + 9 * n_i_, scratch_j9_.begin());
        kernel_.interpolate_transpose(scratch_j9_.data(), scratch_k9_.data(), changed, 9);
        for (const unsigned int k : changed)
          {
            const double *q = &scratch_k9_[9 * k];
            const double *x = &xi_[3 * k];
            for (unsigned int i = 0; i < 3; ++i)
              f[3 * k + i] -= q[3 * i] * x[0] + q[3 * i + 1] * x[1] + q[3 * i + 2] * x[2];
          }
      }
    if (!residual)
      return 0.;
    const CsrView &a = smoothing_.interpolation();
    for (const unsigned int i : owned_a)
      residual_row(a, d, i);
    smoothing_.interpolate_transpose(scratch_j_.data(), scratch_k_.data(), changed, 3);
    const double alpha = options_.residual_coefficient;
    for (const unsigned int k : changed)
      for (unsigned int c = 0; c < 3; ++c)
        {
          if (k < n_i_)
            f[3 * k + c] -= alpha * scratch_j_[3 * k + c];
          f[3 * k + c] += alpha * scratch_k_[3 * k + c];
        }
    double energy = 0;
    for (unsigned int i = 0; i < n_i_; ++i)
      energy += residual_energy_[i];
    return energy;
  }

  void
  SpgOperator::integration_terms(const double *volume, const double *area_vector, double *c, double *b,
                                 double *w) const
  {
    std::fill(scratch_j9_.begin(), scratch_j9_.end(), 0.);
    for (unsigned int i = 0; i < n_i_; ++i)
      for (unsigned int d = 0; d < 3; ++d)
        scratch_j9_[9 * i + 4 * d] = volume[i];
    kernel_.internal_force(scratch_j9_.data(), c);
    std::fill(scratch_j_.begin(), scratch_j_.end(), 0.);
    std::copy(area_vector, area_vector + 3 * n_i_, scratch_j_.begin());
    kernel_.interpolate_transpose(scratch_j_.data(), b, 3);
    std::fill(scratch_j_.begin(), scratch_j_.end(), 0.);
    std::copy(volume, volume + n_i_, scratch_j_.begin());
    kernel_.interpolate_transpose(scratch_j_.data(), w, 1);
  }

  void
  SpgOperator::set_gradient_correction(std::vector<double> xi)
  {
    if (!xi.empty() && xi.size() != 3 * n_k_)
      throw std::invalid_argument("SpgOperator: one correction vector per coefficient expected");
    xi_ = std::move(xi);
  }

  void
  SpgOperator::smooth_owned(const double *in, double *out) const
  {
    const CsrView &a = smoothing_.interpolation();
    base::for_each_range(n_i_, rows_per_task, [&](const unsigned int begin, const unsigned int end) {
      for (unsigned int i = begin; i < end; ++i)
        {
          double s[3] = {0, 0, 0};
          for (unsigned int e = a.offsets[i]; e < a.offsets[i + 1]; ++e)
            for (unsigned int c = 0; c < 3; ++c)
              s[c] += a.values[e] * in[3 * a.columns[e] + c];
          for (unsigned int c = 0; c < 3; ++c)
            out[3 * i + c] = s[c];
        }
    });
  }

  namespace
  {
    /// Allocated bytes of a std::vector (its capacity).
    template <typename T>
    std::size_t
    vector_bytes(const std::vector<T> &v)
    {
      return v.capacity() * sizeof(T);
    }

    /// Allocated bytes of the arrays of a Stencil.
    std::size_t
    stencil_bytes(const Stencil &s)
    {
      return vector_bytes(s.row_offsets) + vector_bytes(s.columns) + vector_bytes(s.psi) + vector_bytes(s.grad) +
             vector_bytes(s.fallback) + vector_bytes(s.rcond);
    }

  } // namespace

  std::size_t
  LocalStencils::memory_consumption() const
  {
    return sizeof(*this) + stencil_bytes(a) + stencil_bytes(g) + vector_bytes(cloud_index) + vector_bytes(fallback);
  }

  std::size_t
  SpgOperator::memory_consumption() const
  {
    return sizeof(*this) + vector_bytes(identity_offsets_) + vector_bytes(identity_columns_) +
           vector_bytes(identity_values_) + kernel_.memory_consumption() + smoothing_.memory_consumption() + vector_bytes(lambda_) +
           vector_bytes(xi_) + vector_bytes(scratch_j_) + vector_bytes(scratch_j9_) +
           vector_bytes(scratch_k_) + vector_bytes(scratch_k9_);
  }

} // namespace shard::particles
