// SPDX-License-Identifier: LGPL-2.1-or-later
#include <shard/base/parallel.h>
#include <shard/particles/spg_kernel.h>

#include <algorithm>
#include <cmath>
#include <stdexcept>

namespace shard::particles
{
  namespace
  {
    /// One term P_a . G of scatter 1, with the roundings spelled out (std::fma), so that the
    /// gather and the push give the same bits whatever the compiler contracts elsewhere.
    inline double
    gradient_term(const double *p, const double *gr)
    {
      return std::fma(p[2], gr[2], std::fma(p[1], gr[1], p[0] * gr[0]));
    }

    /// Rows per task of the threaded passes (a fixed partition; each row is written by one task).
    constexpr unsigned int rows_per_task = 1024;

    /// Builds the transposed index of @p m with @p n_columns columns.
    void
    transpose(const CsrView &m, const unsigned int n_columns, std::vector<unsigned int> &offsets,
              std::vector<unsigned int> &rows, std::vector<unsigned int> &entries)
    {
      offsets.assign(n_columns + 1, 0);
      const unsigned int n_entries = m.offsets[m.n_rows];
      for (unsigned int e = 0; e < n_entries; ++e)
        {
          if (m.columns[e] >= n_columns)
            throw std::out_of_range("SpgKernel: stencil column out of range");
          ++offsets[m.columns[e] + 1];
        }
      for (unsigned int c = 0; c < n_columns; ++c)
        offsets[c + 1] += offsets[c];
      rows.resize(n_entries);
      entries.resize(n_entries);
      std::vector<unsigned int> next(offsets.begin(), offsets.end() - 1);
      // Rows in increasing order, so each transposed row lists its entries in a fixed order:
      // results do not depend on how the forward rows were distributed.
      for (unsigned int r = 0; r < m.n_rows; ++r)
        for (unsigned int e = m.offsets[r]; e < m.offsets[r + 1]; ++e)
          {
            const unsigned int slot = next[m.columns[e]]++;
            rows[slot]              = r;
            entries[slot]           = e;
          }
    }
  } // namespace

  void
  SpgKernel::reinit(const CsrView &interpolation, const CsrView &smoothing_gradient,
                    const unsigned int n_coefficients)
  {
    if (interpolation.width != 1 || smoothing_gradient.width != 3)
      throw std::invalid_argument("SpgKernel: A needs width 1 and G width 3");
    a_              = interpolation;
    g_              = smoothing_gradient;
    n_coefficients_ = n_coefficients;
    transpose(a_, n_coefficients, at_offsets_, at_rows_, at_entries_);
    transpose(g_, a_.n_rows, gt_offsets_, gt_rows_, gt_entries_);
    g_scratch_.assign(3 * a_.n_rows, 0.);
    at_values_.clear();
    gt_values_.clear();
    at_slot_.clear();
    gt_slot_.clear();
    if (base::n_threads() > 1)
      {
        // The slot of every forward entry in the transposed order (structure only).
        const std::size_t n_a = at_entries_.size(), n_g = gt_entries_.size();
        at_values_.resize(n_a);
        gt_values_.resize(3 * n_g);
        at_slot_.resize(n_a);
        gt_slot_.resize(n_g);
        for (std::size_t t = 0; t < n_a; ++t)
          at_slot_[at_entries_[t]] = static_cast<unsigned int>(t);
        for (std::size_t t = 0; t < n_g; ++t)
          gt_slot_[gt_entries_[t]] = static_cast<unsigned int>(t);
      }
    copy_transposed_values();
  }

  void
  SpgKernel::copy_transposed_values()
  {
    for (std::size_t t = 0; t < at_values_.size(); ++t)
      at_values_[t] = a_.values[at_entries_[t]];
    for (std::size_t t = 0; t < gt_slot_.size(); ++t)
      for (unsigned int c = 0; c < 3; ++c)
        gt_values_[3 * t + c] = g_.values[3 * std::size_t(gt_entries_[t]) + c];
  }

  void
  SpgKernel::copy_transposed_values(const std::vector<unsigned int> &a_rows, const std::vector<unsigned int> &g_rows)
  {
    if (at_values_.empty() && gt_values_.empty())
      return;
    for (const unsigned int r : a_rows)
      if (r < a_.n_rows)
        for (unsigned int e = a_.offsets[r]; e < a_.offsets[r + 1]; ++e)
          at_values_[at_slot_[e]] = a_.values[e];
    for (const unsigned int r : g_rows)
      if (r < g_.n_rows)
        for (unsigned int e = g_.offsets[r]; e < g_.offsets[r + 1]; ++e)
          for (unsigned int c = 0; c < 3; ++c)
            gt_values_[3 * std::size_t(gt_slot_[e]) + c] = g_.values[3 * std::size_t(e) + c];
  }

  std::size_t
  SpgKernel::memory_consumption() const
  {
    const auto bytes = [](const auto &v) { return v.capacity() * sizeof(v[0]); };
    return bytes(at_offsets_) + bytes(at_rows_) + bytes(at_entries_) + bytes(gt_offsets_) + bytes(gt_rows_) +
           bytes(gt_entries_) + bytes(at_values_) + bytes(gt_values_) + bytes(at_slot_) + bytes(gt_slot_) +
           bytes(g_scratch_) + bytes(mark_);
  }

  // The per-row sums below serve both the full passes and the passes over listed rows, so a
  // partial refresh gives exactly the values of a full evaluation.
  inline void
  SpgKernel::interpolate_row(const double *d, double *u, const unsigned int j) const
  {
    double s0 = 0, s1 = 0, s2 = 0;
    for (unsigned int e = a_.offsets[j]; e < a_.offsets[j + 1]; ++e)
      {
        const double  w  = a_.values[e];
        const double *dk = d + 3 * a_.columns[e];
        s0 += w * dk[0];
        s1 += w * dk[1];
        s2 += w * dk[2];
      }
    u[3 * j]     = s0;
    u[3 * j + 1] = s1;
    u[3 * j + 2] = s2;
  }

  inline void
  SpgKernel::deformation_gradient_row(const double *u, double *F, const unsigned int i) const
  {
    double f[9] = {1, 0, 0, 0, 1, 0, 0, 0, 1};
    for (unsigned int e = g_.offsets[i]; e < g_.offsets[i + 1]; ++e)
      {
        const double *gr = g_.values + 3 * e;
        const double *uj = u + 3 * g_.columns[e];
        for (unsigned int a = 0; a < 3; ++a)
          for (unsigned int b = 0; b < 3; ++b)
            f[3 * a + b] += uj[a] * gr[b];
      }
    for (unsigned int k = 0; k < 9; ++k)
      F[9 * i + k] = f[k];
  }

  inline void
  SpgKernel::gradient_transpose_row(const double *VP, double *g, const unsigned int j) const
  {
    double s[3] = {0, 0, 0};
    const double *copy = gt_values_.empty() ? nullptr : gt_values_.data();
    for (unsigned int t = gt_offsets_[j]; t < gt_offsets_[j + 1]; ++t)
      {
        const double *p  = VP + 9 * gt_rows_[t];
        const double *gr = copy != nullptr ? copy + 3 * std::size_t(t) : g_.values + 3 * std::size_t(gt_entries_[t]);
        for (unsigned int a = 0; a < 3; ++a)
          s[a] += gradient_term(p + 3 * a, gr);
      }
    g[3 * j]     = s[0];
    g[3 * j + 1] = s[1];
    g[3 * j + 2] = s[2];
  }

  inline void
  SpgKernel::interpolate_transpose_row(const double *g, double *f, const unsigned int k, const unsigned int width) const
  {
    const double *copy = at_values_.empty() ? nullptr : at_values_.data();
    if (width == 3)
      {
        double s0 = 0, s1 = 0, s2 = 0;
        for (unsigned int t = at_offsets_[k]; t < at_offsets_[k + 1]; ++t)
          {
            const double  w  = copy != nullptr ? copy[t] : a_.values[at_entries_[t]];
            const double *gj = g + 3 * at_rows_[t];
            s0 = std::fma(w, gj[0], s0);
            s1 = std::fma(w, gj[1], s1);
            s2 = std::fma(w, gj[2], s2);
          }
        f[3 * k]     = s0;
        f[3 * k + 1] = s1;
        f[3 * k + 2] = s2;
        return;
      }
    double s[9] = {0, 0, 0, 0, 0, 0, 0, 0, 0};
    for (unsigned int t = at_offsets_[k]; t < at_offsets_[k + 1]; ++t)
      {
        const double  w  = copy != nullptr ? copy[t] : a_.values[at_entries_[t]];
        const double *gj = g + width * at_rows_[t];
        for (unsigned int c = 0; c < width; ++c)
          s[c] = std::fma(w, gj[c], s[c]);
      }
    for (unsigned int c = 0; c < width; ++c)
      f[width * k + c] = s[c];
  }

  void
  SpgKernel::interpolate(const double *d, double *u) const
  {
    base::for_each_range(a_.n_rows, rows_per_task, [&](const unsigned int begin, const unsigned int end) {
      for (unsigned int j = begin; j < end; ++j)
        interpolate_row(d, u, j);
    });
  }

  void
  SpgKernel::deformation_gradient(const double *u, double *F) const
  {
    base::for_each_range(g_.n_rows, rows_per_task, [&](const unsigned int begin, const unsigned int end) {
      for (unsigned int i = begin; i < end; ++i)
        deformation_gradient_row(u, F, i);
    });
  }

  void
  SpgKernel::gradient_transpose(const double *VP, double *g) const
  {
    if (base::n_threads() == 1)
      {
        // One thread: a row-wise push, which streams through G instead of reaching every entry
        // through the transposed index. Each g_J receives its terms in the order of the
        // transposed index (rows I ascending, then entries), from zero, with the same
        // roundings (gradient_term, std::fma): bitwise the gather below (test
        // threads.same_history.*).
        std::fill(g, g + 3 * a_.n_rows, 0.);
        for (unsigned int i = 0; i < g_.n_rows; ++i)
          {
            const double *p = VP + 9 * i;
            for (unsigned int e = g_.offsets[i]; e < g_.offsets[i + 1]; ++e)
              {
                const double *gr = g_.values + 3 * e;
                double       *gj = g + 3 * g_.columns[e];
                for (unsigned int a = 0; a < 3; ++a)
                  gj[a] += gradient_term(p + 3 * a, gr);
              }
          }
        return;
      }
    base::for_each_range(a_.n_rows, rows_per_task, [&](const unsigned int begin, const unsigned int end) {
      for (unsigned int j = begin; j < end; ++j)
        gradient_transpose_row(VP, g, j);
    });
  }

  void
  SpgKernel::interpolate_transpose(const double *g, double *f, const unsigned int width) const
  {
    if (width == 0 || width > 9)
      throw std::invalid_argument("SpgKernel::interpolate_transpose: width must be 1 to 9");
    if (base::n_threads() == 1)
      {
        // One thread: the row-wise push of A^T, bitwise the gather (see gradient_transpose()).
        std::fill(f, f + width * n_coefficients_, 0.);
        for (unsigned int j = 0; j < a_.n_rows; ++j)
          {
            const double *gj = g + width * j;
            for (unsigned int e = a_.offsets[j]; e < a_.offsets[j + 1]; ++e)
              {
                const double w  = a_.values[e];
                double      *fk = f + width * a_.columns[e];
                for (unsigned int c = 0; c < width; ++c)
                  fk[c] = std::fma(w, gj[c], fk[c]);
              }
          }
        return;
      }
    base::for_each_range(n_coefficients_, rows_per_task, [&](const unsigned int begin, const unsigned int end) {
      for (unsigned int k = begin; k < end; ++k)
        interpolate_transpose_row(g, f, k, width);
    });
  }

  void
  SpgKernel::interpolate(const double *d, double *u, const std::vector<unsigned int> &rows) const
  {
    for (const unsigned int j : rows)
      interpolate_row(d, u, j);
  }

  void
  SpgKernel::deformation_gradient(const double *u, double *F, const std::vector<unsigned int> &rows) const
  {
    for (const unsigned int i : rows)
      deformation_gradient_row(u, F, i);
  }

  void
  SpgKernel::gradient_transpose(const double *VP, double *g, const std::vector<unsigned int> &rows) const
  {
    for (const unsigned int j : rows)
      gradient_transpose_row(VP, g, j);
  }

  void
  SpgKernel::interpolate_transpose(const double *g, double *f, const std::vector<unsigned int> &rows,
                                   const unsigned int width) const
  {
    if (width == 0 || width > 9)
      throw std::invalid_argument("SpgKernel::interpolate_transpose: width must be 1 to 9");
    for (const unsigned int k : rows)
      interpolate_transpose_row(g, f, k, width);
  }

  namespace
  {
    /// The marked indices in increasing order; clears the marks.
    std::vector<unsigned int>
    collect(std::vector<unsigned char> &mark)
    {
      std::vector<unsigned int> out;
      for (unsigned int c = 0; c < mark.size(); ++c)
        if (mark[c])
          {
            out.push_back(c);
            mark[c] = 0;
          }
      return out;
    }

    /// Columns of the rows @p rows of @p m, sorted without duplicates (marks, no sort).
    std::vector<unsigned int>
    columns_of(const CsrView &m, const std::vector<unsigned int> &rows, const unsigned int n_columns,
               std::vector<unsigned char> &mark)
    {
      mark.assign(n_columns, 0);
      for (const unsigned int r : rows)
        for (unsigned int e = m.offsets[r]; e < m.offsets[r + 1]; ++e)
          mark[m.columns[e]] = 1;
      return collect(mark);
    }
  } // namespace

  std::vector<unsigned int>
  SpgKernel::interpolation_columns(const std::vector<unsigned int> &rows) const
  {
    return columns_of(a_, rows, n_coefficients_, mark_);
  }

  std::vector<unsigned int>
  SpgKernel::gradient_columns(const std::vector<unsigned int> &rows) const
  {
    return columns_of(g_, rows, a_.n_rows, mark_);
  }

  std::vector<unsigned int>
  SpgKernel::gradient_rows_using(const std::vector<unsigned int> &columns) const
  {
    mark_.assign(g_.n_rows, 0);
    for (const unsigned int c : columns)
      if (c + 1 < gt_offsets_.size())
        for (unsigned int t = gt_offsets_[c]; t < gt_offsets_[c + 1]; ++t)
          mark_[gt_rows_[t]] = 1;
    return collect(mark_);
  }

  void
  SpgKernel::internal_force(const double *VP, double *f) const
  {
    gradient_transpose(VP, g_scratch_.data());
    interpolate_transpose(g_scratch_.data(), f, 3);
  }
} // namespace shard::particles
