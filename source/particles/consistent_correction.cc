// SPDX-License-Identifier: LGPL-2.1-or-later
#include <shard/base/parallel.h>
#include <shard/particles/consistent_correction.h>

#include <Eigen/Dense>
#include <Eigen/CholmodSupport>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <iterator>
#include <map>
#include <numeric>
#include <memory>
#include <stdexcept>
#include <string>
#include <unordered_map>

namespace shard::particles
{
  ConsistentCorrection::ConsistentCorrection(const LocalStencils &stencils, const std::vector<Point3> &position_j,
                                             const double *volume, const std::vector<char> *fixed)
    : st_(stencils)
    , n_i_(stencils.n_i)
    , n_j_(stencils.n_j)
    , volume_(volume, volume + stencils.n_i)
  {
    if (position_j.size() != n_j_)
      throw std::invalid_argument("ConsistentCorrection: one position per particle J expected");
    if (fixed && fixed->size() != n_i_)
      throw std::invalid_argument("ConsistentCorrection: one fixed flag per owned row expected");
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
        // A stencil that does not span 3-D (a Shepard fallback row) is left uncorrected, and so is
        // a fixed row (its values are given).
        if ((fixed && (*fixed)[i]) || !invert_spd4(m, &inverse_moment_[16 * i]))
          std::fill(&inverse_moment_[16 * i], &inverse_moment_[16 * i] + 16, std::nan(""));
      }
  }

  void
  ConsistentCorrection::row_fit(const unsigned int i, const double *lambda, double *mu) const
  {
    // s_c = sum_J p_J lambda_Jc, one 4-vector of the basis per component c, so that the pass
    // runs as packet operations (Eigen); then mu_c = M^-1 s_c.
    using Vector4    = Eigen::Vector4d;
    const Stencil &g = st_.g;
    Vector4        s0 = Vector4::Zero(), s1 = Vector4::Zero(), s2 = Vector4::Zero();
    for (unsigned int e = g.row_offsets[i]; e < g.row_offsets[i + 1]; ++e)
      {
        const Eigen::Map<const Vector4> p(&basis_[4 * e]);
        const double                   *l = &lambda[3 * g.columns[e]];
        s0 += l[0] * p;
        s1 += l[1] * p;
        s2 += l[2] * p;
      }
    const Eigen::Map<const Eigen::Matrix<double, 4, 4, Eigen::RowMajor>> inv(&inverse_moment_[16 * i]);
    Eigen::Map<Eigen::Matrix<double, 4, 3, Eigen::RowMajor>>             out(mu);
    out.col(0) = inv * s0;
    out.col(1) = inv * s1;
    out.col(2) = inv * s2;
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
    // The hot kernel of the CG loop (one or two applications per iteration): each row's fit
    // (row_fit) and residual in 4-vectors of the basis (p_J = (1, dX / l)), so that both passes
    // run as packet operations (Eigen) instead of 24 scalar multiply-adds per entry.
    using Vector4 = Eigen::Vector4d;
    const Stencil &g = st_.g;
    std::fill(y, y + 3 * n_j_, 0.);
    double mu[12];
    for (unsigned int i = 0; i < n_i_; ++i)
      {
        if (std::isnan(inverse_moment_[16 * i]))
          continue;
        const unsigned int begin = g.row_offsets[i], end = g.row_offsets[i + 1];
        row_fit(i, lambda, mu);
        // mt's rows are mu_c (component c in row c), so mt p = (p_J^T mu_c)_c.
        Eigen::Matrix4d mt = Eigen::Matrix4d::Zero();
        mt.topRows<3>()    = Eigen::Map<const Eigen::Matrix<double, 4, 3, Eigen::RowMajor>>(mu).transpose();
        const double w = volume_[i] * volume_[i];
        for (unsigned int e = begin; e < end; ++e)
          {
            const Eigen::Map<const Vector4> p(&basis_[4 * e]);
            const Vector4                   t = mt * p; // (p_J^T mu_c)_c
            const double                   *l = &lambda[3 * g.columns[e]];
            double                         *o = &y[3 * g.columns[e]];
            for (unsigned int c = 0; c < 3; ++c)
              o[c] += w * (l[c] - t(c));
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
    // The blocks by (aggregate, aggregate): each aggregate (by its first function) has a slot,
    // and each slot a short list of its neighbours' blocks (a row's k aggregates need k lookups
    // in a hash map and k^2 in these lists, not k^2 hash lookups).
    std::vector<Block>                                            blocks;
    std::unordered_map<unsigned int, unsigned int>                slot_of;
    std::vector<unsigned int>                                     first_of_slot;
    std::vector<std::vector<std::pair<unsigned int, unsigned int>>> neighbours; // (first of b, block)
    std::vector<unsigned int>                                     row_slot;
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
        row_slot.clear();
        for (const unsigned int f : agg_first)
          {
            const auto [it, added] = slot_of.emplace(f, static_cast<unsigned int>(first_of_slot.size()));
            if (added)
              {
                first_of_slot.push_back(f);
                neighbours.emplace_back();
              }
            row_slot.push_back(it->second);
          }
        for (unsigned int a = 0; a < agg_first.size(); ++a)
          for (unsigned int b = 0; b < agg_first.size(); ++b)
            {
              auto        &list = neighbours[row_slot[a]];
              unsigned int q    = 0;
              while (q < list.size() && list[q].first != agg_first[b])
                ++q;
              if (q == list.size())
                {
                  list.emplace_back(agg_first[b], static_cast<unsigned int>(blocks.size()));
                  blocks.emplace_back();
                }
              Block &blk  = blocks[list[q].second];
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
    // In block order (a fixed order; a rank's list has no duplicates, so the order does not change
    // the sums on rank 0, which adds the ranks' lists in rank order).
    std::vector<unsigned int> slots(first_of_slot.size());
    std::iota(slots.begin(), slots.end(), 0u);
    std::sort(slots.begin(), slots.end(), [&](const unsigned int x, const unsigned int y) {
      return first_of_slot[x] < first_of_slot[y];
    });
    std::vector<CoarseEntry> out;
    out.reserve(16 * blocks.size());
    for (const unsigned int slot : slots)
      {
        auto &list = neighbours[slot];
        std::sort(list.begin(), list.end());
        for (const auto &[first_b, index] : list)
          {
            const Block &blk = blocks[index];
            for (unsigned int r = 0; r < blk.rows; ++r)
              for (unsigned int c = 0; c < blk.columns; ++c)
                out.push_back({first_of_slot[slot] + r, first_b + c, blk.v[4 * r + c]});
          }
      }
    return out;
  }

  namespace
  {
    /// The component of a particle J that is not an unknown of a patch solve.
    constexpr unsigned int outside = ~0u;

    /**
     * The additive coarse correction of the correction solve: aggregates of particles (cubes of
     * edge H per component, over all ranks), their constant and linear functions, E = Z^T S Z assembled
     * on rank 0 and factorized (CHOLMOD, supernodal Cholesky) there; each preconditioner
     * application sends Z^T r to rank 0 and returns E^-1 Z^T r to the owners.
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
        // The sum over ranks carries round-off that depends on the rank count, and a particle on a
        // cube face would change cube with it: H rounded to 20 bits is the same at any rank count.
        int          exponent = 0;
        const double mantissa = std::frexp(size * h, &exponent);
        const double H        = std::ldexp(std::round(std::ldexp(mantissa, 20)), exponent - 20);

        // Aggregates: the particles of one component in one cube, over all ranks. This rank's part
        // of each (its "local aggregates", in cube order) sends its sums to rank 0, which merges
        // them in rank order, numbers the aggregates in cube order and returns what each part needs:
        // the coarse space is the same at any rank count (decision 0009).
        std::vector<std::array<long long, 4>>             key(n_owned_);
        std::map<std::array<long long, 4>, unsigned int> index;
        for (unsigned int i = 0; i < n_owned_; ++i)
          {
            if (component[i] == outside)
              continue;
            key[i] = {{static_cast<long long>(component[i]), 0, 0, 0}};
            for (unsigned int c = 0; c < 3; ++c)
              key[i][c + 1] = static_cast<long long>(std::floor(position_j[i][c] / H));
            index.emplace(key[i], 0u);
          }
        const unsigned int n_parts = index.size();
        {
          unsigned int n = 0;
          for (auto &entry : index)
            entry.second = n++;
        }
        aggregate_.resize(n_owned_);
        for (unsigned int i = 0; i < n_owned_; ++i)
          aggregate_[i] = component[i] == outside ? outside : index.at(key[i]);
        const auto up = [&](std::vector<double> v) { return exchange.to_root ? exchange.to_root(v) : v; };
        // On rank 0: the number of local aggregates of every rank, the lengths of the parts below
        // (the other ranks need no lengths: from_root reads them on rank 0 only).
        std::vector<int> parts;
        for (const double n : up(std::vector<double>{double(n_parts)}))
          parts.push_back(static_cast<int>(n));
        const auto lengths = [&](const int per_part) {
          std::vector<int> out(parts);
          for (auto &n : out)
            n *= per_part;
          return out;
        };
        const auto down = [&](const std::vector<double> &all, const int per_part) {
          return exchange.from_root ? exchange.from_root(all, lengths(per_part), per_part * n_parts) : all;
        };
        const bool root = exchange.rank == 0;

        // 1. Members and the sum of positions -> the aggregate's number and centroid.
        std::vector<double> send(8 * n_parts, 0.);
        for (const auto &[k, a] : index)
          for (unsigned int c = 0; c < 4; ++c)
            send[8 * a + c] = static_cast<double>(k[c]);
        for (unsigned int i = 0; i < n_owned_; ++i)
          {
            if (aggregate_[i] == outside)
              continue;
            send[8 * aggregate_[i] + 4] += 1.;
            for (unsigned int c = 0; c < 3; ++c)
              send[8 * aggregate_[i] + 5 + c] += position_j[i][c];
          }
        std::vector<double> received = up(send);
        // On rank 0: the aggregate of every part (in rank order), and per aggregate the sums.
        std::vector<unsigned int>    aggregate_of_part;
        std::vector<Eigen::Vector3d> centroid;
        std::vector<double>          members;
        if (root)
          {
            std::vector<std::array<long long, 4>>             part_key(received.size() / 8);
            std::map<std::array<long long, 4>, unsigned int> global;
            for (std::size_t p = 0; p < part_key.size(); ++p)
              {
                for (unsigned int c = 0; c < 4; ++c)
                  part_key[p][c] = static_cast<long long>(received[8 * p + c]);
                global.emplace(part_key[p], 0u);
              }
            n_aggregates_ = 0;
            for (auto &entry : global)
              entry.second = n_aggregates_++;
            centroid.assign(n_aggregates_, Eigen::Vector3d::Zero());
            members.assign(n_aggregates_, 0.);
            aggregate_of_part.resize(part_key.size());
            for (std::size_t p = 0; p < aggregate_of_part.size(); ++p)
              {
                const unsigned int a = global.at(part_key[p]);
                aggregate_of_part[p] = a;
                members[a] += received[8 * p + 4];
                centroid[a] += Eigen::Vector3d(received[8 * p + 5], received[8 * p + 6], received[8 * p + 7]);
              }
            for (unsigned int a = 0; a < n_aggregates_; ++a)
              centroid[a] /= members[a];
            send.assign(3 * aggregate_of_part.size(), 0.);
            for (std::size_t p = 0; p < aggregate_of_part.size(); ++p)
              for (unsigned int c = 0; c < 3; ++c)
                send[3 * p + c] = centroid[aggregate_of_part[p]](c);
          }
        received = down(send, 3);
        std::vector<Eigen::Vector3d> part_centroid(n_parts);
        for (unsigned int a = 0; a < n_parts; ++a)
          part_centroid[a] = Eigen::Vector3d(received[3 * a], received[3 * a + 1], received[3 * a + 2]);

        // 2. Second moments about the centroid -> the principal directions; a direction is kept
        //    when its variance is at least 1 % of the largest one and the aggregate has 4 particles
        //    or more. Rank 0 numbers the functions in aggregate order.
        send.assign(9 * n_parts, 0.);
        for (unsigned int i = 0; i < n_owned_; ++i)
          {
            if (aggregate_[i] == outside)
              continue;
            const Eigen::Vector3d x =
              Eigen::Vector3d(position_j[i][0], position_j[i][1], position_j[i][2]) - part_centroid[aggregate_[i]];
            for (unsigned int r = 0; r < 3; ++r)
              for (unsigned int c = 0; c < 3; ++c)
                send[9 * aggregate_[i] + 3 * r + c] += x(r) * x(c);
          }
        received = up(send);
        if (root)
          {
            std::vector<Eigen::Matrix3d> moment(n_aggregates_, Eigen::Matrix3d::Zero());
            for (std::size_t p = 0; p < aggregate_of_part.size(); ++p)
              for (unsigned int r = 0; r < 3; ++r)
                for (unsigned int c = 0; c < 3; ++c)
                  moment[aggregate_of_part[p]](r, c) += received[9 * p + 3 * r + c];
            std::vector<Eigen::Matrix3d> scaled(n_aggregates_, Eigen::Matrix3d::Zero()); // rows: v_k / sigma_k
            std::vector<unsigned int>    count(n_aggregates_, 1), first(n_aggregates_, 0);
            n_functions_ = 0;
            for (unsigned int a = 0; a < n_aggregates_; ++a)
              {
                first[a] = n_functions_;
                if (members[a] >= 4)
                  {
                    const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eig(moment[a] / members[a]);
                    const double largest = eig.eigenvalues()(2);
                    for (int k = 2; k >= 0; --k)
                      if (largest > 0 && eig.eigenvalues()(k) >= 1e-2 * largest)
                        scaled[a].row(count[a]++ - 1) =
                          eig.eigenvectors().col(k).transpose() / std::sqrt(eig.eigenvalues()(k));
                  }
                n_functions_ += count[a];
              }
            send.assign(11 * aggregate_of_part.size(), 0.);
            function_of_slot_.clear();
            for (std::size_t p = 0; p < aggregate_of_part.size(); ++p)
              {
                const unsigned int a = aggregate_of_part[p];
                send[11 * p]         = first[a];
                send[11 * p + 1]     = count[a];
                for (unsigned int r = 0; r < 3; ++r)
                  for (unsigned int c = 0; c < 3; ++c)
                    send[11 * p + 2 + 3 * r + c] = scaled[a](r, c);
                for (unsigned int k = 0; k < count[a]; ++k)
                  function_of_slot_.push_back(first[a] + k);
              }
            // The lengths of every rank's part of Z^T r: 3 per function of its local aggregates.
            slot_lengths_.assign(parts.size(), 0);
            for (std::size_t r = 0, p = 0; r < parts.size(); ++r)
              for (int q = 0; q < parts[r]; ++q, ++p)
                slot_lengths_[r] += 3 * static_cast<int>(count[aggregate_of_part[p]]);
          }
        received = down(send, 11);
        std::vector<Eigen::Matrix3d> scaled(n_parts);
        std::vector<unsigned int>    first(n_parts), count(n_parts);
        slot_first_.resize(n_parts);
        n_slots_ = 0;
        for (unsigned int a = 0; a < n_parts; ++a)
          {
            first[a] = static_cast<unsigned int>(received[11 * a]);
            count[a] = static_cast<unsigned int>(received[11 * a + 1]);
            for (unsigned int r = 0; r < 3; ++r)
              for (unsigned int c = 0; c < 3; ++c)
                scaled[a](r, c) = received[11 * a + 2 + 3 * r + c];
            slot_first_[a] = n_slots_;
            n_slots_ += count[a];
          }
        // Every rank knows the sizes of the coarse space.
        std::vector<double> sizes{double(n_functions_), double(n_aggregates_)};
        if (!root)
          sizes.assign(2, 0.);
        exchange.sum(sizes);
        n_functions_  = static_cast<unsigned int>(sizes[0]);
        n_aggregates_ = static_cast<unsigned int>(sizes[1]);
        // The functions at every J: owned computed here, the others from their owners.
        std::vector<double> head(3 * n_j, 0.), tail(3 * n_j, 0.);
        for (unsigned int i = 0; i < n_owned_; ++i)
          {
            const unsigned int a = aggregate_[i];
            if (a == outside)
              continue; // no coarse function: first = count = 0
            const Eigen::Vector3d x =
              Eigen::Vector3d(position_j[i][0], position_j[i][1], position_j[i][2]) - part_centroid[a];
            const Eigen::Vector3d phi = scaled[a] * x;
            head[3 * i]               = first[a];
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

        // E = Z^T S Z, assembled and factorized on rank 0 only: the other ranks send their entries
        // and wait for the outcome.
        const auto          local = correction.coarse_operator(functions_);
        std::vector<double> flat(3 * local.size());
        for (std::size_t k = 0; k < local.size(); ++k)
          {
            flat[3 * k]     = local[k].row;
            flat[3 * k + 1] = local[k].column;
            flat[3 * k + 2] = local[k].value;
          }
        if (exchange.to_root)
          flat = exchange.to_root(flat);
        double factorized = 1.;
        if (exchange.rank == 0)
          factorized = factorize(flat) ? 1. : 0.;
        if (exchange.from_root)
          factorized =
            exchange.from_root(std::vector<double>(parts.size(), factorized), std::vector<int>(parts.size(), 1), 1)[0];
        if (factorized != 1.)
          throw std::runtime_error("consistent correction: the coarse matrix could not be factorized");
      }

      /// z += Z E^-1 Z^T r on the owned J (3 per J). Each rank sends its part of Z^T r (per function
      /// of its local aggregates) to rank 0, which adds the parts in rank order, solves with E and
      /// returns to every rank the values of the functions of its local aggregates.
      void
      add(const std::vector<double> &r, std::vector<double> &z) const
      {
        std::vector<double> b(3 * std::size_t(n_slots_), 0.);
        for (unsigned int i = 0; i < n_owned_; ++i)
          for (unsigned int k = 0; k < functions_.count[i]; ++k)
            {
              const double phi = k == 0 ? 1. : functions_.phi[3 * i + k - 1];
              for (unsigned int c = 0; c < 3; ++c)
                b[3 * (slot_first_[aggregate_[i]] + k) + c] += phi * r[3 * i + c];
            }
        if (exchange_.to_root)
          b = exchange_.to_root(b);
        if (exchange_.rank == 0)
          {
            Eigen::Matrix<double, Eigen::Dynamic, 3> rhs = Eigen::Matrix<double, Eigen::Dynamic, 3>::Zero(n_functions_, 3);
            for (std::size_t s = 0; s < function_of_slot_.size(); ++s)
              for (unsigned int c = 0; c < 3; ++c)
                rhs(function_of_slot_[s], c) += b[3 * s + c];
            const Eigen::Matrix<double, Eigen::Dynamic, 3> y = factor_.solve(rhs);
            for (std::size_t s = 0; s < function_of_slot_.size(); ++s)
              for (unsigned int c = 0; c < 3; ++c)
                b[3 * s + c] = y(function_of_slot_[s], c);
          }
        if (exchange_.from_root)
          b = exchange_.from_root(b, slot_lengths_, 3 * n_slots_);
        for (unsigned int i = 0; i < n_owned_; ++i)
          for (unsigned int k = 0; k < functions_.count[i]; ++k)
            {
              const double phi = k == 0 ? 1. : functions_.phi[3 * i + k - 1];
              for (unsigned int c = 0; c < 3; ++c)
                z[3 * i + c] += phi * b[3 * (slot_first_[aggregate_[i]] + k) + c];
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
      const CorrectionExchange &exchange_;
      unsigned int              n_owned_, n_functions_ = 0, n_aggregates_ = 0;
      /// Per owned particle: its local aggregate (this rank's part of an aggregate, in cube order).
      std::vector<unsigned int> aggregate_;
      /// Per local aggregate: its first slot; a slot is one function of a local aggregate.
      std::vector<unsigned int> slot_first_;
      unsigned int              n_slots_ = 0;
      /// On rank 0: the global function of every slot of every rank (in rank order), and the
      /// length of every rank's part of Z^T r (3 per slot).
      std::vector<unsigned int> function_of_slot_;
      std::vector<int>          slot_lengths_;
      CoarseFunctions           functions_;
      /// E, on rank 0 only.
      Eigen::CholmodSupernodalLLT<Eigen::SparseMatrix<double>> factor_;

      /// Assembles E from the entries of all ranks (row, column, value) and factorizes it.
      /// @return false when no shift makes it factorizable
      bool
      factorize(const std::vector<double> &flat)
      {
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
        return factor_.info() == Eigen::Success;
      }
    };

    /// Dot product over the owned entries (3 per owned J), summed over ranks. @note Collective.
    double
    owned_dot(const std::vector<double> &a, const std::vector<double> &b, const unsigned int n_owned,
              const CorrectionExchange &exchange)
    {
      double sum = 0; // a local accumulator: a[k] * b[k] added into a vector's element would be
                      // stored and loaded again in every step (the vectors may alias)
      for (unsigned int k = 0; k < 3 * n_owned; ++k)
        sum += a[k] * b[k];
      std::vector<double> s(1, sum);
      exchange.sum(s);
      return s[0];
    }

    /**
     * The projection onto the range of S, v <- v - p (p^T p)^-1 p^T v per component, with
     * p = (1, X - X_c) and X_c the centroid of each component (a fixed point): removes the
     * fields linear in X, the null space of S. (p^T p)^-1 depends on the positions only.
     */
    class NullSpaceProjection
    {
    public:
      /// Centroids and (p^T p)^-1 of every component. @note Collective.
      NullSpaceProjection(const std::vector<Point3> &position_j, const std::vector<unsigned int> &component,
                          const unsigned int n_components, const CorrectionExchange &exchange)
        : position_j_(position_j)
        , component_(component)
        , n_owned_(component.size())
        , exchange_(exchange)
        , origin_(n_components, Point3{{0, 0, 0}})
        , inverse_(16 * n_components, 0.)
        , invertible_(n_components, 0)
        , moments_(12 * n_components)
        , fit_(12 * n_components)
      {
        std::vector<double> centroid(4 * n_components, 0.);
        for (unsigned int i = 0; i < n_owned_; ++i)
          {
            if (component[i] == outside)
              continue;
            centroid[4 * component[i]] += 1;
            for (unsigned int c = 0; c < 3; ++c)
              centroid[4 * component[i] + 1 + c] += position_j[i][c];
          }
        exchange.sum(centroid);
        for (unsigned int b = 0; b < n_components; ++b)
          for (unsigned int c = 0; c < 3; ++c)
            origin_[b][c] = centroid[4 * b] > 0 ? centroid[4 * b + 1 + c] / centroid[4 * b] : 0.;

        std::vector<double> pp(16 * n_components, 0.);
        for (unsigned int i = 0; i < n_owned_; ++i)
          {
            if (component[i] == outside)
              continue;
            double pv[4];
            basis(i, pv);
            for (unsigned int a = 0; a < 4; ++a)
              for (unsigned int b = 0; b < 4; ++b)
                pp[16 * component[i] + 4 * a + b] += pv[a] * pv[b];
          }
        exchange.sum(pp);
        for (unsigned int b = 0; b < n_components; ++b)
          invertible_[b] = invert_spd4(&pp[16 * b], &inverse_[16 * b]) ? 1 : 0;
      }

      /// Projects @p v (3 per owned J); returns the squared norm removed (over all ranks).
      /// @note Collective.
      double
      project(std::vector<double> &v)
      {
        std::fill(moments_.begin(), moments_.end(), 0.);
        // Runs of one component (the particles are ordered by body) sum into a local array.
        for (unsigned int i = 0; i < n_owned_;)
          {
            const unsigned int b   = component_[i];
            double             m[12] = {};
            if (b == outside)
              {
                ++i;
                continue;
              }
            for (; i < n_owned_ && component_[i] == b; ++i)
              {
                double pv[4];
                basis(i, pv);
                for (unsigned int a = 0; a < 4; ++a)
                  for (unsigned int c = 0; c < 3; ++c)
                    m[3 * a + c] += pv[a] * v[3 * i + c];
              }
            for (unsigned int k = 0; k < 12; ++k)
              moments_[12 * b + k] += m[k];
          }
        exchange_.sum(moments_);
        std::fill(fit_.begin(), fit_.end(), 0.);
        for (unsigned int b = 0; b < invertible_.size(); ++b)
          if (invertible_[b])
            for (unsigned int a = 0; a < 4; ++a)
              for (unsigned int c = 0; c < 3; ++c)
                for (unsigned int k = 0; k < 4; ++k)
                  fit_[12 * b + 3 * a + c] += inverse_[16 * b + 4 * a + k] * moments_[12 * b + 3 * k + c];
        double removed = 0;
        for (unsigned int i = 0; i < n_owned_; ++i)
          {
            if (component_[i] == outside)
              continue;
            double pv[4];
            basis(i, pv);
            for (unsigned int c = 0; c < 3; ++c)
              {
                double w = 0;
                for (unsigned int a = 0; a < 4; ++a)
                  w += pv[a] * fit_[12 * component_[i] + 3 * a + c];
                v[3 * i + c] -= w;
                removed += w * w;
              }
          }
        std::vector<double> total(1, removed);
        exchange_.sum(total);
        return total[0];
      }

    private:
      /// p = (1, X - X_c) of owned particle @p i.
      void
      basis(const unsigned int i, double *pv) const
      {
        pv[0] = 1;
        for (unsigned int c = 0; c < 3; ++c)
          pv[c + 1] = position_j_[i][c] - origin_[component_[i]][c];
      }

      const std::vector<Point3>       &position_j_;
      const std::vector<unsigned int> &component_;
      const unsigned int               n_owned_;
      const CorrectionExchange        &exchange_;
      std::vector<Point3>              origin_;
      std::vector<double>              inverse_;
      std::vector<char>                invertible_;
      std::vector<double>              moments_, fit_;
    };
  } // namespace

  CorrectionSolve
  solve_consistent_correction(const ConsistentCorrection &correction, const double *area,
                              const std::vector<Point3> &position_j, const std::vector<unsigned int> &component,
                              const unsigned int n_components, const CorrectionExchange &exchange,
                              std::vector<double> &lambda, const double tolerance, const unsigned int max_iterations,
                              const double coarse_size, const bool patch)
  {
    const unsigned int n_j = correction.n_j(), n_owned = component.size();
    std::vector<double> r(3 * n_j), z(3 * n_j), p(3 * n_j), q(3 * n_j), diag(3 * n_j);
    lambda.assign(3 * n_j, 0.);
    correction.defect(area, r.data());
    exchange.assemble(r);
    correction.diagonal(diag.data());
    exchange.assemble(diag);
    const auto dot = [&](const std::vector<double> &a, const std::vector<double> &b) {
      return owned_dot(a, b, n_owned, exchange);
    };
    // A patch solve: the particles no corrected row reaches are not unknowns. Their defect is
    // what the fixed rows left there (the caller's to check), not part of this solve's.
    std::vector<unsigned int> patch_component;
    if (patch)
      {
        patch_component = component;
        for (unsigned int i = 0; i < n_owned; ++i)
          if (!(diag[3 * i] > 0))
            {
              patch_component[i] = outside;
              for (unsigned int c = 0; c < 3; ++c)
                r[3 * i + c] = 0.;
            }
      }
    const std::vector<unsigned int> &unknowns = patch ? patch_component : component;
    CorrectionSolve                  out;
    const double                     r_norm = std::sqrt(dot(r, r));

    // Remove the component of r along the null space of S (fields linear in X), per component.
    NullSpaceProjection projection(position_j, unknowns, n_components, exchange);
    const double        removed = projection.project(r);
    out.initial_defect          = r_norm;
    out.inconsistency           = r_norm > 0 ? std::sqrt(removed) / r_norm : 0.;

    std::unique_ptr<CoarseCorrection> coarse;
    if (coarse_size > 0)
      {
        coarse                = std::make_unique<CoarseCorrection>(correction, position_j, unknowns, coarse_size, exchange);
        out.coarse_functions = coarse->n_functions();
        out.aggregates       = coarse->n_aggregates();
      }
    // Preconditioner. Without a coarse space: Jacobi, z = D^-1 r. With one, the two-level
    // "A-DEF2" preconditioner (Tang, Nabben, Vuik, Erlangga 2009), with Q = Z E^-1 Z^T:
    //   z = w + Q (r - S w),  w = D^-1 r,
    // Jacobi for the fine part, then the coarse part of what Jacobi left solved exactly (the
    // additive form Q + D^-1 adds the two approximations instead). Started from x0 = Q r0, so that
    // Z^T r = 0 from the first step, it equals the balancing (BNN) preconditioner in exact
    // arithmetic, which is symmetric; without that start CG does not converge. Measured on the
    // contrib/bench particle block (110 592 particles, coarse size 3): 19 iterations instead of
    // 32 for the additive form (doc/performance.md, "Particle set-up speed"); the extra product
    // S w per iteration costs less than the 13 iterations it saves.
    std::vector<double> w, sw, y;
    if (coarse)
      {
        w.resize(3 * n_j);
        sw.resize(3 * n_j);
        y.resize(3 * n_j);
      }
    // y = Q v, projected: E is shifted along its singular directions (the fields linear over a
    // component), so E^-1 amplifies the round-off of Z^T v there by up to 1e8 / max E_kk; those
    // fields are the null space of S, and left in y they ruin p^T S p (CG broke down on some CPUs).
    const auto coarse_solve = [&](const std::vector<double> &v) {
      std::fill(y.begin(), y.end(), 0.);
      coarse->add(v, y);
      projection.project(y);
    };
    const auto precondition = [&]() {
      if (!coarse)
        {
          for (unsigned int k = 0; k < 3 * n_owned; ++k)
            z[k] = diag[k] > 0 ? r[k] / diag[k] : 0.;
          return;
        }
      for (unsigned int k = 0; k < 3 * n_owned; ++k)
        w[k] = diag[k] > 0 ? r[k] / diag[k] : 0.;
      exchange.distribute(w);
      correction.apply(w.data(), sw.data());
      exchange.assemble(sw);
      for (unsigned int k = 0; k < 3 * n_owned; ++k)
        sw[k] = r[k] - sw[k];
      coarse_solve(sw);
      for (unsigned int k = 0; k < 3 * n_owned; ++k)
        z[k] = w[k] + y[k];
    };
    if (coarse)
      {
        // The deflated start: lambda = Q r, r <- r - S Q r.
        coarse_solve(r);
        std::copy(y.begin(), y.begin() + 3 * n_owned, lambda.begin());
        exchange.distribute(lambda);
        correction.apply(lambda.data(), q.data());
        exchange.assemble(q);
        for (unsigned int k = 0; k < 3 * n_owned; ++k)
          r[k] -= q[k];
      }
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
