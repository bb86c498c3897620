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

    /// Rewrites the columns of @p s through @p map (cloud index -> compact index).
    void
    remap_columns(Stencil &s, const std::vector<unsigned int> &map, const unsigned int n_columns)
    {
      for (auto &c : s.columns)
        c = map[c];
      s.n_columns = n_columns;
    }

    /// Drops the columns of @p pattern whose particle lies in another component than its row.
    void
    filter_components(CsrPattern &pattern, const std::vector<unsigned int> &row_component,
                      const std::vector<unsigned int> &component)
    {
      if (component.empty())
        return;
      unsigned int out = 0, begin = 0;
      for (std::size_t r = 0; r + 1 < pattern.row_offsets.size(); ++r)
        {
          const unsigned int end = pattern.row_offsets[r + 1];
          for (unsigned int e = begin; e < end; ++e)
            if (component[pattern.columns[e]] == row_component[r])
              pattern.columns[out++] = pattern.columns[e];
          begin                    = end;
          pattern.row_offsets[r + 1] = out;
        }
      pattern.columns.resize(out);
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
    if (cloud.spacing.size() != n || cloud.interpolating.size() != n ||
        (!cloud.component.empty() && cloud.component.size() != n))
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
    CsrPattern n_owned = find_support_neighbors(xi, cloud.position, radii, params.support);
    const auto components_of = [&](const std::vector<unsigned int> &cloud_rows) {
      std::vector<unsigned int> c;
      if (!cloud.component.empty())
        for (const unsigned int p : cloud_rows)
          c.push_back(cloud.component[p]);
      return c;
    };
    filter_components(n_owned, components_of(owned), cloud.component);
    for (const unsigned int c : n_owned.columns)
      add(c);
    out.n_j = out.cloud_index.size();

    // A rows: RK values at every particle J.
    std::vector<Point3> xj(out.n_j);
    for (unsigned int j = 0; j < out.n_j; ++j)
      xj[j] = cloud.position[out.cloud_index[j]];
    CsrPattern n_j = find_support_neighbors(xj, cloud.position, radii, params.support);
    filter_components(n_j, components_of(out.cloud_index), cloud.component);
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

  ConsistentCorrection::ConsistentCorrection(const LocalStencils &stencils, const std::vector<Point3> &position_j,
                                             const double *volume)
    : st_(stencils)
    , n_i_(stencils.n_i)
    , n_j_(stencils.n_j)
    , volume_(volume, volume + stencils.n_i)
  {
    if (position_j.size() != n_j_)
      throw std::invalid_argument("ConsistentCorrection: one position per particle J expected");
    const Stencil &g = st_.g;
    basis_.resize(4 * g.columns.size());
    inverse_moment_.resize(16 * n_i_);
    row_length_.resize(n_i_);
    for (unsigned int i = 0; i < n_i_; ++i)
      {
        const Point3 &xi = position_j[i];
        double        l  = 0;
        for (unsigned int e = g.row_offsets[i]; e < g.row_offsets[i + 1]; ++e)
          for (unsigned int c = 0; c < 3; ++c)
            l = std::max(l, std::abs(position_j[g.columns[e]][c] - xi[c]));
        l = l > 0 ? l : 1.;
        row_length_[i] = l;
        double m[16] = {};
        for (unsigned int e = g.row_offsets[i]; e < g.row_offsets[i + 1]; ++e)
          {
            double *p = &basis_[4 * e];
            p[0]      = 1;
            for (unsigned int c = 0; c < 3; ++c)
              p[c + 1] = (position_j[g.columns[e]][c] - xi[c]) / l;
            for (unsigned int r = 0; r < 4; ++r)
              for (unsigned int c = 0; c < 4; ++c)
                m[4 * r + c] += p[r] * p[c];
          }
        // A stencil that does not span 3-D (a Shepard fallback row) is left uncorrected.
        if (!invert_spd4(m, &inverse_moment_[16 * i]))
          std::fill(&inverse_moment_[16 * i], &inverse_moment_[16 * i] + 16, std::nan(""));
      }
  }

  void
  ConsistentCorrection::row_fit(const unsigned int i, const double *lambda, double *mu) const
  {
    const Stencil &g = st_.g;
    double         s[12] = {};
    for (unsigned int e = g.row_offsets[i]; e < g.row_offsets[i + 1]; ++e)
      {
        const double *p = &basis_[4 * e];
        const double *l = &lambda[3 * g.columns[e]];
        for (unsigned int r = 0; r < 4; ++r)
          for (unsigned int c = 0; c < 3; ++c)
            s[3 * r + c] += p[r] * l[c];
      }
    const double *inv = &inverse_moment_[16 * i];
    for (unsigned int r = 0; r < 4; ++r)
      for (unsigned int c = 0; c < 3; ++c)
        mu[3 * r + c] = inv[4 * r] * s[c] + inv[4 * r + 1] * s[3 + c] + inv[4 * r + 2] * s[6 + c] +
                        inv[4 * r + 3] * s[9 + c];
  }

  void
  ConsistentCorrection::defect(const double *area, double *r) const
  {
    const Stencil &g = st_.g;
    std::fill(r, r + 3 * n_j_, 0.);
    for (unsigned int i = 0; i < n_i_; ++i)
      {
        for (unsigned int c = 0; c < 3; ++c)
          r[3 * i + c] += area[3 * i + c];
        for (unsigned int e = g.row_offsets[i]; e < g.row_offsets[i + 1]; ++e)
          for (unsigned int c = 0; c < 3; ++c)
            r[3 * g.columns[e] + c] -= volume_[i] * g.grad[3 * e + c];
      }
  }

  void
  ConsistentCorrection::apply(const double *lambda, double *y) const
  {
    const Stencil &g = st_.g;
    std::fill(y, y + 3 * n_j_, 0.);
    double mu[12];
    for (unsigned int i = 0; i < n_i_; ++i)
      {
        if (std::isnan(inverse_moment_[16 * i]))
          continue;
        row_fit(i, lambda, mu);
        const double w = volume_[i] * volume_[i];
        for (unsigned int e = g.row_offsets[i]; e < g.row_offsets[i + 1]; ++e)
          {
            const double *p = &basis_[4 * e];
            const double *l = &lambda[3 * g.columns[e]];
            for (unsigned int c = 0; c < 3; ++c)
              y[3 * g.columns[e] + c] +=
                w * (l[c] - p[0] * mu[c] - p[1] * mu[3 + c] - p[2] * mu[6 + c] - p[3] * mu[9 + c]);
          }
      }
  }

  void
  ConsistentCorrection::diagonal(double *diag) const
  {
    const Stencil &g = st_.g;
    std::fill(diag, diag + 3 * n_j_, 0.);
    for (unsigned int i = 0; i < n_i_; ++i)
      {
        if (std::isnan(inverse_moment_[16 * i]))
          continue;
        const double *inv = &inverse_moment_[16 * i];
        const double  w   = volume_[i] * volume_[i];
        for (unsigned int e = g.row_offsets[i]; e < g.row_offsets[i + 1]; ++e)
          {
            const double *p  = &basis_[4 * e];
            double        pp = 0; // (P_I)_JJ = p_J^T M^-1 p_J
            for (unsigned int r = 0; r < 4; ++r)
              for (unsigned int c = 0; c < 4; ++c)
                pp += p[r] * inv[4 * r + c] * p[c];
            for (unsigned int c = 0; c < 3; ++c)
              diag[3 * g.columns[e] + c] += w * (1 - pp);
          }
      }
  }

  std::vector<double>
  ConsistentCorrection::corrected_gradients(const double *lambda) const
  {
    const Stencil      &g = st_.g;
    limited_rows_          = 0;
    std::vector<double> out(g.grad.begin(), g.grad.begin() + 3 * std::size_t(g.row_offsets[n_i_]));
    double              mu[12];
    for (unsigned int i = 0; i < n_i_; ++i)
      {
        if (std::isnan(inverse_moment_[16 * i]))
          continue;
        row_fit(i, lambda, mu);
        // Limiter: no entry of a row's correction exceeds max_correction_ratio / l_I (l_I the
        // largest coordinate distance in the stencil, the spacing on a lattice). Scaling the
        // row's correction keeps linear exactness (its sums vanish) and gives up part of the
        // integration constraint at that row only.
        const auto correction = [&](const unsigned int e, const unsigned int c) {
          const double *p = &basis_[4 * e];
          const double *l = &lambda[3 * g.columns[e]];
          return volume_[i] * (l[c] - p[0] * mu[c] - p[1] * mu[3 + c] - p[2] * mu[6 + c] - p[3] * mu[9 + c]);
        };
        double largest = 0;
        for (unsigned int e = g.row_offsets[i]; e < g.row_offsets[i + 1]; ++e)
          for (unsigned int c = 0; c < 3; ++c)
            largest = std::max(largest, std::abs(correction(e, c)));
        const double bound = max_correction_ratio / row_length_[i];
        const double scale = largest > bound ? bound / largest : 1.;
        if (scale < 1.)
          ++limited_rows_;
        for (unsigned int e = g.row_offsets[i]; e < g.row_offsets[i + 1]; ++e)
          for (unsigned int c = 0; c < 3; ++c)
            out[3 * e + c] += scale * correction(e, c);
      }
    return out;
  }

  std::vector<CoarseEntry>
  ConsistentCorrection::coarse_operator(const CoarseFunctions &functions) const
  {
    const Stencil &g = st_.g;
    struct Block
    {
      std::array<double, 16> v{};
      unsigned char          rows = 0, columns = 0;
    };
    std::unordered_map<std::uint64_t, Block> blocks;
    // Per row: the aggregates of its stencil (first function, count, first column in T).
    std::vector<unsigned int> agg_first, agg_column;
    std::vector<unsigned char> agg_count;
    std::vector<double>       t, u, d; // T (4 x n_col), M^-1 T, diagonal blocks (16 per aggregate)
    std::vector<unsigned int> entry_agg;
    for (unsigned int i = 0; i < n_i_; ++i)
      {
        if (std::isnan(inverse_moment_[16 * i]))
          continue;
        agg_first.clear();
        agg_count.clear();
        agg_column.clear();
        entry_agg.clear();
        unsigned int n_col = 0;
        for (unsigned int e = g.row_offsets[i]; e < g.row_offsets[i + 1]; ++e)
          {
            const unsigned int f = functions.first[g.columns[e]];
            unsigned int       a = 0;
            while (a < agg_first.size() && agg_first[a] != f)
              ++a;
            if (a == agg_first.size())
              {
                agg_first.push_back(f);
                agg_count.push_back(functions.count[g.columns[e]]);
                agg_column.push_back(n_col);
                n_col += agg_count.back();
              }
            entry_agg.push_back(a);
          }
        if (agg_first.size() < 2)
          continue;
        t.assign(4 * n_col, 0.);
        d.assign(16 * agg_first.size(), 0.);
        for (unsigned int e = g.row_offsets[i], k = 0; e < g.row_offsets[i + 1]; ++e, ++k)
          {
            const unsigned int a   = entry_agg[k];
            const unsigned int j   = g.columns[e];
            const double       z[4] = {1., functions.phi[3 * j], functions.phi[3 * j + 1], functions.phi[3 * j + 2]};
            const double      *p   = &basis_[4 * e];
            const unsigned int n   = agg_count[a];
            for (unsigned int r = 0; r < n; ++r)
              {
                for (unsigned int c = 0; c < n; ++c)
                  d[16 * a + 4 * r + c] += z[r] * z[c];
                for (unsigned int q = 0; q < 4; ++q)
                  t[n_col * q + agg_column[a] + r] += p[q] * z[r];
              }
          }
        const double *inv = &inverse_moment_[16 * i];
        u.assign(4 * n_col, 0.);
        for (unsigned int q = 0; q < 4; ++q)
          for (unsigned int s = 0; s < 4; ++s)
            for (unsigned int c = 0; c < n_col; ++c)
              u[n_col * q + c] += inv[4 * q + s] * t[n_col * s + c];
        const double w = volume_[i] * volume_[i];
        for (unsigned int a = 0; a < agg_first.size(); ++a)
          for (unsigned int b = 0; b < agg_first.size(); ++b)
            {
              Block &blk  = blocks[(std::uint64_t(agg_first[a]) << 32) | agg_first[b]];
              blk.rows    = agg_count[a];
              blk.columns = agg_count[b];
              for (unsigned int r = 0; r < agg_count[a]; ++r)
                for (unsigned int c = 0; c < agg_count[b]; ++c)
                  {
                    double v = a == b ? d[16 * a + 4 * r + c] : 0.;
                    for (unsigned int q = 0; q < 4; ++q)
                      v -= t[n_col * q + agg_column[a] + r] * u[n_col * q + agg_column[b] + c];
                    blk.v[4 * r + c] += w * v;
                  }
            }
      }
    std::vector<CoarseEntry> out;
    out.reserve(16 * blocks.size());
    for (const auto &[key, blk] : blocks)
      for (unsigned int r = 0; r < blk.rows; ++r)
        for (unsigned int c = 0; c < blk.columns; ++c)
          out.push_back({static_cast<unsigned int>(key >> 32) + r, static_cast<unsigned int>(key & 0xffffffffu) + c,
                         blk.v[4 * r + c]});
    std::sort(out.begin(), out.end(), [](const CoarseEntry &x, const CoarseEntry &y) {
      return x.row != y.row ? x.row < y.row : x.column < y.column;
    });
    return out;
  }

  namespace
  {
    /**
     * The additive coarse correction of the correction solve: aggregates of owned particles
     * (cubes of edge H per component), their constant and linear functions, E = Z^T S Z assembled
     * over all ranks and factorized (CHOLMOD, supernodal Cholesky) on every rank.
     */
    class CoarseCorrection
    {
    public:
      CoarseCorrection(const ConsistentCorrection &correction, const std::vector<Point3> &position_j,
                       const std::vector<unsigned int> &component, const double size, const CorrectionExchange &exchange)
        : exchange_(exchange)
        , n_owned_(component.size())
      {
        const unsigned int n_j = correction.n_j();
        // The edge H: size times the mean spacing (cube root of the mean volume), over all ranks.
        std::vector<double> totals{0., double(n_owned_)};
        for (unsigned int i = 0; i < correction.n_i(); ++i)
          totals[0] += correction.volume(i);
        exchange.sum(totals);
        const double h = totals[1] > 0 ? std::cbrt(totals[0] / totals[1]) : 1.;
        const double H = size * h;

        // Aggregates of the owned particles, numbered in the order of their cube (deterministic).
        std::vector<std::array<long long, 4>>             key(n_owned_);
        std::map<std::array<long long, 4>, unsigned int> index;
        for (unsigned int i = 0; i < n_owned_; ++i)
          {
            key[i] = {{static_cast<long long>(component[i]), 0, 0, 0}};
            for (unsigned int c = 0; c < 3; ++c)
              key[i][c + 1] = static_cast<long long>(std::floor(position_j[i][c] / H));
            index.emplace(key[i], 0u);
          }
        {
          unsigned int n = 0;
          for (auto &entry : index)
            entry.second = n++;
          n_aggregates_ = n;
        }
        std::vector<unsigned int> aggregate(n_owned_);
        for (unsigned int i = 0; i < n_owned_; ++i)
          aggregate[i] = index.at(key[i]);
        // Per aggregate: centroid and principal directions; a direction is kept when its
        // variance is at least 1 % of the largest one and the aggregate has 4 particles or more.
        std::vector<Eigen::Vector3d> centroid(n_aggregates_, Eigen::Vector3d::Zero());
        std::vector<Eigen::Matrix3d> moment(n_aggregates_, Eigen::Matrix3d::Zero());
        std::vector<unsigned int>    members(n_aggregates_, 0);
        for (unsigned int i = 0; i < n_owned_; ++i)
          {
            centroid[aggregate[i]] += Eigen::Vector3d(position_j[i][0], position_j[i][1], position_j[i][2]);
            ++members[aggregate[i]];
          }
        for (unsigned int a = 0; a < n_aggregates_; ++a)
          centroid[a] /= members[a];
        for (unsigned int i = 0; i < n_owned_; ++i)
          {
            const Eigen::Vector3d x =
              Eigen::Vector3d(position_j[i][0], position_j[i][1], position_j[i][2]) - centroid[aggregate[i]];
            moment[aggregate[i]] += x * x.transpose();
          }
        std::vector<Eigen::Matrix3d> scaled(n_aggregates_, Eigen::Matrix3d::Zero()); // rows: v_k / sigma_k
        std::vector<unsigned int>    count(n_aggregates_, 1), local_first(n_aggregates_, 0);
        unsigned int                 n_local = 0;
        for (unsigned int a = 0; a < n_aggregates_; ++a)
          {
            local_first[a] = n_local;
            if (members[a] >= 4)
              {
                const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eig(moment[a] / members[a]);
                const double largest = eig.eigenvalues()(2);
                for (int k = 2; k >= 0; --k)
                  if (largest > 0 && eig.eigenvalues()(k) >= 1e-2 * largest)
                    scaled[a].row(count[a]++ - 1) = eig.eigenvectors().col(k).transpose() / std::sqrt(eig.eigenvalues()(k));
              }
            n_local += count[a];
          }
        // Global numbering: the functions of the ranks before this one come first.
        unsigned int offset = 0;
        n_functions_        = n_local;
        if (exchange.gather)
          {
            const auto counts = exchange.gather(std::vector<double>{double(n_local)});
            n_functions_      = 0;
            for (unsigned int r = 0; r < counts.size(); ++r)
              {
                if (r < exchange.rank)
                  offset += static_cast<unsigned int>(counts[r]);
                n_functions_ += static_cast<unsigned int>(counts[r]);
              }
          }
        // The functions at every J: owned computed here, the others from their owners.
        std::vector<double> head(3 * n_j, 0.), tail(3 * n_j, 0.);
        for (unsigned int i = 0; i < n_owned_; ++i)
          {
            const unsigned int    a = aggregate[i];
            const Eigen::Vector3d x =
              Eigen::Vector3d(position_j[i][0], position_j[i][1], position_j[i][2]) - centroid[a];
            const Eigen::Vector3d phi = scaled[a] * x;
            head[3 * i]               = offset + local_first[a];
            head[3 * i + 1]           = count[a];
            head[3 * i + 2]           = count[a] > 1 ? phi(0) : 0.;
            tail[3 * i]               = count[a] > 2 ? phi(1) : 0.;
            tail[3 * i + 1]           = count[a] > 3 ? phi(2) : 0.;
          }
        exchange.distribute(head);
        exchange.distribute(tail);
        functions_.first.resize(n_j);
        functions_.count.resize(n_j);
        functions_.phi.resize(3 * n_j);
        for (unsigned int j = 0; j < n_j; ++j)
          {
            functions_.first[j]       = static_cast<unsigned int>(head[3 * j]);
            functions_.count[j]       = static_cast<unsigned char>(head[3 * j + 1]);
            functions_.phi[3 * j]     = head[3 * j + 2];
            functions_.phi[3 * j + 1] = tail[3 * j];
            functions_.phi[3 * j + 2] = tail[3 * j + 1];
          }

        // E over all ranks, factorized on every rank.
        const auto          local = correction.coarse_operator(functions_);
        std::vector<double> flat(3 * local.size());
        for (std::size_t k = 0; k < local.size(); ++k)
          {
            flat[3 * k]     = local[k].row;
            flat[3 * k + 1] = local[k].column;
            flat[3 * k + 2] = local[k].value;
          }
        if (exchange.gather)
          flat = exchange.gather(flat);
        std::vector<Eigen::Triplet<double>> triplets;
        triplets.reserve(flat.size() / 3 + n_functions_);
        std::vector<double> diagonal(n_functions_, 0.);
        for (std::size_t k = 0; k < flat.size(); k += 3)
          {
            const auto r = static_cast<int>(flat[k]), c = static_cast<int>(flat[k + 1]);
            triplets.emplace_back(r, c, flat[k + 2]);
            if (r == c)
              diagonal[r] += flat[k + 2];
          }
        // E is singular along the fields linear over a whole component (and along functions no
        // row couples): a small shift makes it definite; the right-hand sides Z^T r are
        // orthogonal to those directions, so the shift changes the correction by round-off only.
        const double largest = diagonal.empty() ? 0. : *std::max_element(diagonal.begin(), diagonal.end());
        for (unsigned int k = 0; k < n_functions_; ++k)
          triplets.emplace_back(k, k, diagonal[k] > 1e-10 * largest ? 1e-8 * largest : std::max(largest, 1.));
        Eigen::SparseMatrix<double> e(n_functions_, n_functions_);
        e.setFromTriplets(triplets.begin(), triplets.end());
        factor_.compute(e);
        // Round-off may leave a pivot of a singular direction negative: shift more and retry.
        for (double extra = 1e-6 * largest; factor_.info() != Eigen::Success && extra <= largest; extra *= 100)
          {
            Eigen::SparseMatrix<double> shifted = e;
            for (unsigned int k = 0; k < n_functions_; ++k)
              shifted.coeffRef(k, k) += extra;
            factor_.compute(shifted);
          }
        if (factor_.info() != Eigen::Success)
          throw std::runtime_error("consistent correction: the coarse matrix could not be factorized");
      }

      /// z += Z E^-1 Z^T r on the owned J (3 per J).
      void
      add(const std::vector<double> &r, std::vector<double> &z) const
      {
        std::vector<double> b(3 * std::size_t(n_functions_), 0.);
        for (unsigned int i = 0; i < n_owned_; ++i)
          for (unsigned int k = 0; k < functions_.count[i]; ++k)
            {
              const double phi = k == 0 ? 1. : functions_.phi[3 * i + k - 1];
              for (unsigned int c = 0; c < 3; ++c)
                b[3 * (functions_.first[i] + k) + c] += phi * r[3 * i + c];
            }
        exchange_.sum(b);
        Eigen::Map<Eigen::Matrix<double, Eigen::Dynamic, 3, Eigen::RowMajor>> rhs(b.data(), n_functions_, 3);
        const Eigen::Matrix<double, Eigen::Dynamic, 3> y = factor_.solve(Eigen::Matrix<double, Eigen::Dynamic, 3>(rhs));
        for (unsigned int i = 0; i < n_owned_; ++i)
          for (unsigned int k = 0; k < functions_.count[i]; ++k)
            {
              const double phi = k == 0 ? 1. : functions_.phi[3 * i + k - 1];
              for (unsigned int c = 0; c < 3; ++c)
                z[3 * i + c] += phi * y(functions_.first[i] + k, c);
            }
      }

      unsigned int
      n_functions() const
      {
        return n_functions_;
      }

      unsigned int
      n_aggregates() const
      {
        return n_aggregates_;
      }

    private:
      const CorrectionExchange                          &exchange_;
      unsigned int                                       n_owned_, n_functions_ = 0, n_aggregates_ = 0;
      CoarseFunctions                                    functions_;
      Eigen::CholmodSupernodalLLT<Eigen::SparseMatrix<double>> factor_;
    };
  } // namespace

  CorrectionSolve
  solve_consistent_correction(const ConsistentCorrection &correction, const double *area,
                              const std::vector<Point3> &position_j, const std::vector<unsigned int> &component,
                              const unsigned int n_components, const CorrectionExchange &exchange,
                              std::vector<double> &lambda, const double tolerance, const unsigned int max_iterations,
                              const double coarse_size)
  {
    const unsigned int n_j = correction.n_j(), n_owned = component.size();
    std::vector<double> r(3 * n_j), z(3 * n_j), p(3 * n_j), q(3 * n_j), diag(3 * n_j);
    lambda.assign(3 * n_j, 0.);
    correction.defect(area, r.data());
    exchange.assemble(r);
    correction.diagonal(diag.data());
    exchange.assemble(diag);
    const auto dot = [&](const std::vector<double> &a, const std::vector<double> &b) {
      std::vector<double> s(1, 0.);
      for (unsigned int k = 0; k < 3 * n_owned; ++k)
        s[0] += a[k] * b[k];
      exchange.sum(s);
      return s[0];
    };
    CorrectionSolve out;
    const double    r_norm = std::sqrt(dot(r, r));

    // Remove the component of r along the null space of S (fields linear in X), per component:
    // r <- r - p (p^T p)^-1 p^T r with p = (1, X - X_c), X_c a fixed point of each component.
    std::vector<Point3> origin(n_components, Point3{{0, 0, 0}});
    {
      std::vector<double> centroid(4 * n_components, 0.);
      for (unsigned int i = 0; i < n_owned; ++i)
        {
          centroid[4 * component[i]] += 1;
          for (unsigned int c = 0; c < 3; ++c)
            centroid[4 * component[i] + 1 + c] += position_j[i][c];
        }
      exchange.sum(centroid);
      for (unsigned int b = 0; b < n_components; ++b)
        for (unsigned int c = 0; c < 3; ++c)
          origin[b][c] = centroid[4 * b] > 0 ? centroid[4 * b + 1 + c] / centroid[4 * b] : 0.;
    }
    const auto basis = [&](const unsigned int i, double *pv) {
      pv[0] = 1;
      for (unsigned int c = 0; c < 3; ++c)
        pv[c + 1] = position_j[i][c] - origin[component[i]][c];
    };
    // The projection onto the range of S, v <- v - p (p^T p)^-1 p^T v per component; returns
    // the squared norm removed (over all ranks). (p^T p)^-1 depends on the positions only.
    std::vector<double> inverse(16 * n_components, 0.);
    std::vector<char>   invertible(n_components, 0);
    {
      std::vector<double> pp(16 * n_components, 0.);
      for (unsigned int i = 0; i < n_owned; ++i)
        {
          double pv[4];
          basis(i, pv);
          for (unsigned int a = 0; a < 4; ++a)
            for (unsigned int b = 0; b < 4; ++b)
              pp[16 * component[i] + 4 * a + b] += pv[a] * pv[b];
        }
      exchange.sum(pp);
      for (unsigned int b = 0; b < n_components; ++b)
        invertible[b] = invert_spd4(&pp[16 * b], &inverse[16 * b]) ? 1 : 0;
    }
    std::vector<double> moments(12 * n_components), fit(12 * n_components);
    const auto          project = [&](std::vector<double> &v) {
      std::fill(moments.begin(), moments.end(), 0.);
      for (unsigned int i = 0; i < n_owned; ++i)
        {
          double pv[4];
          basis(i, pv);
          for (unsigned int a = 0; a < 4; ++a)
            for (unsigned int c = 0; c < 3; ++c)
              moments[12 * component[i] + 3 * a + c] += pv[a] * v[3 * i + c];
        }
      exchange.sum(moments);
      std::fill(fit.begin(), fit.end(), 0.);
      for (unsigned int b = 0; b < n_components; ++b)
        if (invertible[b])
          for (unsigned int a = 0; a < 4; ++a)
            for (unsigned int c = 0; c < 3; ++c)
              for (unsigned int k = 0; k < 4; ++k)
                fit[12 * b + 3 * a + c] += inverse[16 * b + 4 * a + k] * moments[12 * b + 3 * k + c];
      double removed = 0;
      for (unsigned int i = 0; i < n_owned; ++i)
        {
          double pv[4];
          basis(i, pv);
          for (unsigned int c = 0; c < 3; ++c)
            {
              double w = 0;
              for (unsigned int a = 0; a < 4; ++a)
                w += pv[a] * fit[12 * component[i] + 3 * a + c];
              v[3 * i + c] -= w;
              removed += w * w;
            }
        }
      std::vector<double> total(1, removed);
      exchange.sum(total);
      return total[0];
    };
    const double removed = project(r);
    out.initial_defect = r_norm;
    out.inconsistency  = r_norm > 0 ? std::sqrt(removed) / r_norm : 0.;

    std::unique_ptr<CoarseCorrection> coarse;
    if (coarse_size > 0)
      {
        coarse                = std::make_unique<CoarseCorrection>(correction, position_j, component, coarse_size, exchange);
        out.coarse_functions = coarse->n_functions();
        std::vector<double> n(1, coarse->n_aggregates());
        exchange.sum(n);
        out.aggregates = static_cast<unsigned int>(n[0]);
      }
    const auto precondition = [&]() {
      for (unsigned int k = 0; k < 3 * n_owned; ++k)
        z[k] = diag[k] > 0 ? r[k] / diag[k] : 0.;
      if (coarse)
        {
          coarse->add(r, z);
          // E is shifted along its singular directions (the fields linear over a component), so
          // E^-1 amplifies the round-off of Z^T r there by up to 1e8 / max E_kk; those fields are
          // the null space of S, and left in z they ruin p^T S p (CG broke down on some CPUs).
          // Projecting z keeps the preconditioner symmetric on the range of S, where r lives.
          project(z);
        }
    };
    precondition();
    p = z;
    exchange.distribute(p);
    double       rz     = dot(r, z);
    double       res    = std::sqrt(dot(r, r));
    const double target = tolerance * std::max(r_norm, 1e-300);
    while (res > target && out.iterations < max_iterations)
      {
        correction.apply(p.data(), q.data());
        exchange.assemble(q);
        const double pq = dot(p, q);
        if (!(pq > 0))
          break;
        const double alpha = rz / pq;
        for (unsigned int k = 0; k < 3 * n_owned; ++k)
          {
            lambda[k] += alpha * p[k];
            r[k] -= alpha * q[k];
          }
        precondition();
        const double rz_new = dot(r, z);
        const double beta   = rz_new / rz;
        rz                  = rz_new;
        for (unsigned int k = 0; k < 3 * n_owned; ++k)
          p[k] = z[k] + beta * p[k];
        exchange.distribute(p);
        res = std::sqrt(dot(r, r));
        ++out.iterations;
      }
    exchange.distribute(lambda);
    out.final_defect = res;
    out.converged    = res <= target;
    return out;
  }
} // namespace shard::particles
