// SPDX-License-Identifier: LGPL-2.1-or-later
#include <shard/particles/local_stencils.h>
#include <shard/particles/neighbor_build.h>

#include <algorithm>
#include <stdexcept>
#include <vector>

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

    // A rows: RK values at every particle J. The owned J are the rows of G (the same points and
    // the same neighbours: the bins depend on the cloud only), so only the other J (this rank's
    // halo) are evaluated again.
    const unsigned int  n_halo = out.n_j - out.n_i;
    std::vector<Point3> xh(n_halo);
    for (unsigned int h = 0; h < n_halo; ++h)
      xh[h] = cloud.position[out.cloud_index[out.n_i + h]];
    CsrPattern n_h;
    if (n_halo > 0)
      {
        n_h = find_support_neighbors(xh, cloud.position, radii, params.support);
        filter_components(n_h, components_of(std::vector<unsigned int>(out.cloud_index.begin() + out.n_i,
                                                                       out.cloud_index.end())),
                          cloud.component);
        for (const unsigned int c : n_h.columns)
          add(c);
      }
    out.n_k = out.cloud_index.size();

    out.g = build_rk_stencil(xi, cloud.position, radii, n_owned, params);
    for (unsigned int i = 0; i < out.n_i; ++i)
      if (out.g.fallback[i])
        out.fallback.push_back(owned[i]);
    remap_columns(out.g, compact, out.n_j);

    Stencil a;
    if (n_halo > 0)
      {
        a = build_rk_stencil(xh, cloud.position, radii, n_h, params);
        remap_columns(a, compact, out.n_k);
      }
    // Identity rows where the particle interpolates (essential and traction boundaries).
    out.a.row_offsets.assign(1, 0u);
    out.a.n_columns = out.n_k;
    for (unsigned int j = 0; j < out.n_j; ++j)
      {
        const bool     owned_row = j < out.n_i;
        const Stencil &from      = owned_row ? out.g : a;
        const unsigned int row   = owned_row ? j : j - out.n_i;
        if (cloud.interpolating[out.cloud_index[j]])
          {
            out.a.columns.push_back(j);
            out.a.psi.push_back(1.);
          }
        else
          for (unsigned int e = from.row_offsets[row]; e < from.row_offsets[row + 1]; ++e)
            {
              out.a.columns.push_back(from.columns[e]);
              out.a.psi.push_back(from.psi[e]);
            }
        out.a.fallback.push_back(from.fallback[row]);
        out.a.rcond.push_back(from.rcond[row]);
        out.a.row_offsets.push_back(out.a.columns.size());
      }
    return out;
  }

} // namespace shard::particles
