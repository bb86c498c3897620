// SPDX-License-Identifier: LGPL-2.1-or-later
#include <shard/particles/neighbor_build.h>
#include <shard/particles/spg_operator.h>

#include <algorithm>
#include <stdexcept>
#include <string>

namespace shard::particles
{
  namespace
  {
    /// Rewrites the columns of @p s through @p map (cloud index -> compact index).
    void
    remap_columns(Stencil &s, const std::vector<unsigned int> &map, const unsigned int n_columns)
    {
      for (auto &c : s.columns)
        c = map[c];
      s.n_columns = n_columns;
    }

    CsrView
    view(const Stencil &s, const bool gradient)
    {
      return CsrView{s.n_rows(), s.row_offsets.data(), s.columns.data(),
                     gradient ? s.grad.data() : s.psi.data(), gradient ? 3u : 1u};
    }
  } // namespace

  LocalStencils
  build_local_stencils(const ParticleCloud &cloud, const std::vector<unsigned int> &owned,
                       const RkParameters &params)
  {
    const unsigned int n = cloud.position.size();
    if (cloud.spacing.size() != n || cloud.interpolating.size() != n)
      throw std::invalid_argument("build_local_stencils: cloud arrays differ in length");
    const auto radii = support_radii_from_spacing(cloud.spacing, params);

    constexpr unsigned int none = ~0u;
    std::vector<unsigned int> compact(n, none);
    LocalStencils             out;
    const auto add = [&](const unsigned int p) {
      if (compact[p] == none)
        {
          compact[p] = out.cloud_index.size();
          out.cloud_index.push_back(p);
        }
    };
    for (const unsigned int p : owned)
      {
        if (p >= n || compact[p] != none)
          throw std::invalid_argument("build_local_stencils: owned indices must be distinct cloud indices");
        add(p);
      }
    out.n_i = out.cloud_index.size();

    // G rows: gradients of the RK functions at the owned particles.
    std::vector<Point3> xi(out.n_i);
    for (unsigned int i = 0; i < out.n_i; ++i)
      xi[i] = cloud.position[owned[i]];
    const CsrPattern n_owned = find_support_neighbors(xi, cloud.position, radii, params.support);
    for (const unsigned int c : n_owned.columns)
      add(c);
    out.n_j = out.cloud_index.size();

    // A rows: RK values at every particle J.
    std::vector<Point3> xj(out.n_j);
    for (unsigned int j = 0; j < out.n_j; ++j)
      xj[j] = cloud.position[out.cloud_index[j]];
    const CsrPattern n_j = find_support_neighbors(xj, cloud.position, radii, params.support);
    for (const unsigned int c : n_j.columns)
      add(c);
    out.n_k = out.cloud_index.size();

    out.g = build_rk_stencil(xi, cloud.position, radii, n_owned, params);
    for (unsigned int i = 0; i < out.n_i; ++i)
      if (out.g.fallback[i])
        out.fallback.push_back(owned[i]);
    remap_columns(out.g, compact, out.n_j);

    Stencil a = build_rk_stencil(xj, cloud.position, radii, n_j, params);
    remap_columns(a, compact, out.n_k);
    // Identity rows where the particle interpolates (essential and traction boundaries).
    out.a.row_offsets.assign(1, 0u);
    out.a.n_columns = out.n_k;
    for (unsigned int j = 0; j < out.n_j; ++j)
      {
        if (cloud.interpolating[out.cloud_index[j]])
          {
            out.a.columns.push_back(j);
            out.a.psi.push_back(1.);
          }
        else
          for (unsigned int e = a.row_offsets[j]; e < a.row_offsets[j + 1]; ++e)
            {
              out.a.columns.push_back(a.columns[e]);
              out.a.psi.push_back(a.psi[e]);
            }
        out.a.fallback.push_back(a.fallback[j]);
        out.a.rcond.push_back(a.rcond[j]);
        out.a.row_offsets.push_back(out.a.columns.size());
      }
    return out;
  }

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
    for (unsigned int k = 0; k < 3 * n_k_; ++k)
      f[k] -= scratch_k_[k];
    if (xi_.empty())
      return;
    // Correction sum_I V_I P_I xi_K Psi_K(X_I): one more transposed gather of V P with A.
    std::copy(VP, VP + 9 * n_i_, scratch_j9_.begin());
    kernel_.interpolate_transpose(scratch_j9_.data(), scratch_k9_.data(), 9);
    for (unsigned int k = 0; k < n_k_; ++k)
      {
        const double *q = &scratch_k9_[9 * k];
        const double *x = &xi_[3 * k];
        for (unsigned int i = 0; i < 3; ++i)
          f[3 * k + i] -= q[3 * i] * x[0] + q[3 * i + 1] * x[1] + q[3 * i + 2] * x[2];
      }
  }

  double
  SpgOperator::subtract_residual_force(const double *d, double *f) const
  {
    const CsrView &a = smoothing_.interpolation();
    // w_I = Lambda_I (d_I - (A d)_I) on the owned rows, zero on the other rows J.
    double *w      = scratch_j_.data();
    double  energy = 0;
    for (unsigned int i = 0; i < n_i_; ++i)
      {
        double s[3] = {d[3 * i], d[3 * i + 1], d[3 * i + 2]};
        for (unsigned int e = a.offsets[i]; e < a.offsets[i + 1]; ++e)
          for (unsigned int c = 0; c < 3; ++c)
            s[c] -= a.values[e] * d[3 * a.columns[e] + c];
        for (unsigned int c = 0; c < 3; ++c)
          {
            energy += 0.5 * options_.residual_coefficient * lambda_[i] * s[c] * s[c];
            w[3 * i + c] = lambda_[i] * s[c];
          }
      }
    std::fill(w + 3 * n_i_, w + 3 * n_j_, 0.);
    // f -= alpha (I - A)^T w.
    smoothing_.interpolate_transpose(w, scratch_k_.data(), 3);
    const double alpha = options_.residual_coefficient;
    for (unsigned int k = 0; k < 3 * n_i_; ++k)
      f[k] -= alpha * w[k];
    for (unsigned int k = 0; k < 3 * n_k_; ++k)
      f[k] += alpha * scratch_k_[k];
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
    for (unsigned int i = 0; i < n_i_; ++i)
      {
        double s[3] = {0, 0, 0};
        for (unsigned int e = a.offsets[i]; e < a.offsets[i + 1]; ++e)
          for (unsigned int c = 0; c < 3; ++c)
            s[c] += a.values[e] * in[3 * a.columns[e] + c];
        for (unsigned int c = 0; c < 3; ++c)
          out[3 * i + c] = s[c];
      }
  }
} // namespace shard::particles
