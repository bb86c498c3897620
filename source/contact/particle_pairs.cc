// SPDX-License-Identifier: LGPL-2.1-or-later
#include <shard/base/binary_archive.h>
#include <shard/contact/particle_pairs.h>

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <string>

namespace shard::contact
{
  namespace
  {
    double
    norm(const Vec3 &a)
    {
      return std::sqrt(a[0] * a[0] + a[1] * a[1] + a[2] * a[2]);
    }

    unsigned long long
    pair_key(const std::array<unsigned int, 2> &pair)
    {
      return (static_cast<unsigned long long>(pair[0]) << 32) | pair[1];
    }
  } // namespace

  void
  ParticlePairs::reset(const ContactNodes &)
  {
    candidates_.clear();
    dormant_ = Dormant();
    offset_.clear();
  }

  double
  ParticlePairs::stable_dt(const ContactNodes &nodes) const
  {
    // Two masses on one spring: the reduced mass m/2.
    return node_spring_dt(nodes, 0.5);
  }

  void
  ParticlePairs::build(const SearchContext &context)
  {
    // Carry the offsets of the pairs over to the new candidate list: (key, offset) sorted by key
    // and searched by bisection (a hash map of them was 4 % of the showcase).
    std::vector<std::pair<unsigned long long, double>> kept;
    for (std::size_t p = 0; p < offset_.size(); ++p)
      if (offset_[p] >= 0)
        kept.emplace_back(pair_key(candidates_[p]), offset_[p]);
    std::sort(kept.begin(), kept.end());
    search(context);
    offset_.assign(candidates_.size(), -1.);
    for (std::size_t p = 0; p < candidates_.size() && !kept.empty(); ++p)
      {
        const unsigned long long key = pair_key(candidates_[p]);
        const auto it = std::lower_bound(kept.begin(), kept.end(), key,
                                         [](const std::pair<unsigned long long, double> &a,
                                            const unsigned long long b) { return a.first < b; });
        if (it != kept.end() && it->first == key)
          offset_[p] = it->second;
      }
  }

  void
  ParticlePairs::search(const SearchContext &context)
  {
    const auto        &nodes = context.nodes;
    const auto        &x     = context.x;
    const auto        &reach = context.reach;
    const double       base  = context.base;
    const double       largest_radius = context.largest_radius;
    const unsigned int n     = nodes.size();
    auto              &cand  = candidates_;
    cand.clear();
    Dormant &dormant = dormant_;
    dormant          = Dormant();
    std::vector<unsigned char> is_member(n, 0);
    for (unsigned int i = 0; i < n; ++i)
      is_member[i] = nodes.nodes[i].particle && nodes.member(i, settings_.bodies);
    // Each pair is found from the node of larger reach (the smaller index on a tie), whose reach
    // covers both: found holds (finder, other) of the pairs within r_I + r_J + reach_I + reach_J.
    std::vector<std::array<unsigned int, 2>> found;
    const auto close = [&](const unsigned int i, const unsigned int j) {
      const Vec3   dx{{x[j][0] - x[i][0], x[j][1] - x[i][1], x[j][2] - x[i][2]}};
      const double r  = nodes.nodes[i].radius + nodes.nodes[j].radius + reach[i] + reach[j];
      const double d2 = dx[0] * dx[0] + dx[1] * dx[1] + dx[2] * dx[2];
      // Clearly farther (most pairs of the sweep) without the root; the root decides near the
      // limit.
      return !(d2 > r * r * (1 + 1e-12)) && norm(dx) < r;
    };
    // The particles of the interaction in a grid of their own (no FE nodes to skip).
    std::vector<unsigned int> members;
    std::vector<Vec3>         members_x;
    for (unsigned int i = 0; i < n; ++i)
      if (is_member[i])
        {
          members.push_back(i);
          members_x.push_back(x[i]);
        }
    BinGrid member_grid;
    member_grid.build(members_x, 2. * largest_radius + 2. * base);
    // Two slow particles (reach skin/2) in contact range are closer than the cell edge,
    // 2 r_max + skin: one sweep over neighbouring cells finds them, each pair once. Pairs farther
    // than that are dropped on the member positions, before any look-up by node.
    const double widest_slow = (2. * largest_radius + 2. * base) * (2. * largest_radius + 2. * base) * (1 + 1e-12);
    member_grid.for_each_neighbour_pair([&](const unsigned int p, const unsigned int q) {
      const Vec3  &a = members_x[p], &b = members_x[q];
      const double d0 = b[0] - a[0], d1 = b[1] - a[1], d2 = b[2] - a[2];
      if (d0 * d0 + d1 * d1 + d2 * d2 > widest_slow)
        return;
      const unsigned int i = members[std::min(p, q)], j = members[std::max(p, q)];
      if (reach[i] == base && reach[j] == base && close(i, j))
        found.push_back({{i, j}});
    });
    // A fast particle finds the partners of smaller reach around it.
    for (unsigned int i = 0; i < n; ++i)
      {
        if (!is_member[i] || reach[i] == base)
          continue;
        const double r = nodes.nodes[i].radius + largest_radius + 2. * reach[i];
        member_grid.for_each_in_box(Vec3{{x[i][0] - r, x[i][1] - r, x[i][2] - r}},
                                    Vec3{{x[i][0] + r, x[i][1] + r, x[i][2] + r}}, [&](const unsigned int t) {
                                      const unsigned int j = members[t];
                                      if (j == i || reach[j] > reach[i] || (reach[j] == reach[i] && j < i))
                                        return;
                                      if (close(i, j))
                                        found.push_back({{i, j}});
                                    });
      }
    // In the order of the finder, then of the other (a counting sort by the finder and a short
    // sort per finder): the lists do not depend on the grid's cell order.
    std::vector<unsigned int> first(n + 1, 0);
    for (const auto &f : found)
      ++first[f[0] + 1];
    for (unsigned int i = 0; i < n; ++i)
      first[i + 1] += first[i];
    std::vector<unsigned int> others(found.size());
    {
      std::vector<unsigned int> next(first.begin(), first.end() - 1);
      for (const auto &f : found)
        others[next[f[0]]++] = f[1];
    }
    for (unsigned int i = 0; i < n; ++i)
      {
        std::sort(others.begin() + first[i], others.begin() + first[i + 1]);
        for (unsigned int t = first[i]; t < first[i + 1]; ++t)
          {
            const unsigned int a = std::min(i, others[t]), b = std::max(i, others[t]);
            // A pair is evaluated on the rank that owns its particle of smaller DOF (the node
            // list is sorted by DOF).
            if (!nodes.nodes[a].owned)
              continue;
            if (!context.bonds.bonded(nodes, a, b))
              cand.push_back({{a, b}});
            else
              dormant.pairs.push_back({{a, b}});
          }
      }
    dormant.woken.assign(dormant.pairs.size(), 0);
    dormant.offsets.assign(n + 1, 0);
    for (const auto &pair : dormant.pairs)
      ++dormant.offsets[pair[0] + 1], ++dormant.offsets[pair[1] + 1];
    for (unsigned int i = 0; i < n; ++i)
      dormant.offsets[i + 1] += dormant.offsets[i];
    dormant.of_node.resize(dormant.offsets[n]);
    std::vector<unsigned int> next(dormant.offsets.begin(), dormant.offsets.end() - 1);
    for (unsigned int p = 0; p < dormant.pairs.size(); ++p)
      for (const unsigned int i : dormant.pairs[p])
        dormant.of_node[next[i]++] = p;
  }

  void
  ParticlePairs::wake(const BondNews &news)
  {
    Dormant &dormant = dormant_;
    if (dormant.offsets.empty())
      return;
    const auto wake_pair = [&](const unsigned int p) {
      if (dormant.woken[p])
        return;
      dormant.woken[p] = 1;
      candidates_.push_back(dormant.pairs[p]);
      offset_.push_back(-1.);
    };
    for (const auto &[i, j] : news.broken)
      for (unsigned int t = dormant.offsets[i]; t < dormant.offsets[i + 1]; ++t)
        {
          const auto &pair = dormant.pairs[dormant.of_node[t]];
          if (pair[0] == j || pair[1] == j)
            wake_pair(dormant.of_node[t]);
        }
    for (const unsigned int i : news.freed)
      for (unsigned int t = dormant.offsets[i]; t < dormant.offsets[i + 1]; ++t)
        wake_pair(dormant.of_node[t]);
  }

  void
  ParticlePairs::add_forces(const ContactNodes &nodes, unsigned int, double, ForceSink &sink)
  {
    const auto        &in = settings_;
    const auto        &state  = nodes.state;
    constexpr unsigned stride = ContactNodes::state_record;
    for (std::size_t p = 0; p < candidates_.size(); ++p)
      {
        const unsigned int i = candidates_[p][0], j = candidates_[p][1];
        const ContactNode &ni = nodes.nodes[i], &nj = nodes.nodes[j];
        double            &offset = offset_[p];
        // Clearly apart (most candidates): no overlap, so the offset is forgotten.
        {
          const double *a = &state[stride * i], *b = &state[stride * j];
          const double  d0 = b[0] - a[0], d1 = b[1] - a[1], d2 = b[2] - a[2];
          const double  reach = ni.radius + nj.radius;
          if (d0 * d0 + d1 * d1 + d2 * d2 > reach * reach * (1 + 1e-12))
            {
              offset = 0;
              continue;
            }
        }
        SphereHit h = sphere_pair(nodes.position(i), nodes.position(j), ni.radius, nj.radius);
        offset      = std::min(offset < 0 ? std::max(h.overlap, 0.) : offset, std::max(h.overlap, 0.));
        h.overlap -= offset;
        if (h.overlap <= 0)
          continue;
        const double k      = in.penalty * std::min(ni.bulk, nj.bulk) * std::min(ni.spacing, nj.spacing);
        const double spring = k * h.overlap;
        sink.stored += 0.5 * spring * h.overlap;
        double fn = spring;
        Vec3   vr{{0, 0, 0}}; // velocity of j relative to i
        if (in.damping > 0 || in.friction > 0)
          {
            const Vec3 vi = nodes.velocity(i), vj = nodes.velocity(j);
            vr            = Vec3{{vj[0] - vi[0], vj[1] - vi[1], vj[2] - vi[2]}};
          }
        if (in.damping > 0)
          {
            const double mi = ni.mass, mj = nj.mass;
            fn = sink.damped_normal(spring, k, mi + mj > 0 ? mi * mj / (mi + mj) : 0.,
                                    vr[0] * h.normal[0] + vr[1] * h.normal[1] + vr[2] * h.normal[2], in.damping);
          }
        Vec3 fj{{fn * h.normal[0], fn * h.normal[1], fn * h.normal[2]}};
        if (in.friction > 0)
          sink.add_friction(vr, h.normal, fn, in.friction, fj);
        sink.add(j, fj, 1.);
        sink.add(i, fj, -1.);
      }
  }

  void
  ParticlePairs::save(base::BinaryWriter &out) const
  {
    out.put(std::string("particles"));
    out.put(candidates_);
    out.put(dormant_.pairs);
    out.put(dormant_.woken);
    out.put(dormant_.offsets);
    out.put(dormant_.of_node);
    out.put(offset_);
  }

  void
  ParticlePairs::load(base::BinaryReader &in)
  {
    in.expect("particles");
    in.get(candidates_);
    in.get(dormant_.pairs);
    in.get(dormant_.woken);
    in.get(dormant_.offsets);
    in.get(dormant_.of_node);
    in.get(offset_);
  }

  void
  ParticlePairs::write_state(base::BinaryWriter &out, const ContactNodes &, const NodeNaming &naming) const
  {
    std::vector<std::pair<unsigned long long, unsigned long long>> pairs;
    std::vector<double>                                            offsets;
    for (std::size_t q = 0; q < candidates_.size() && q < offset_.size(); ++q)
      if (offset_[q] >= 0)
        {
          pairs.emplace_back(naming.name(candidates_[q][0]), naming.name(candidates_[q][1]));
          offsets.push_back(offset_[q]);
        }
    out.put(pairs);
    out.put(offsets);
  }

  void
  ParticlePairs::read_state(base::BinaryReader &in, const ContactNodes &, const std::vector<int> &,
                            const NodeNaming &naming)
  {
    std::vector<std::pair<unsigned long long, unsigned long long>> pairs;
    std::vector<double>                                            offsets;
    in.get(pairs);
    in.get(offsets);
    if (pairs.size() != offsets.size())
      throw std::runtime_error("the particle contact state does not fit its node list");
    // The next build (Contact's built flag is false) keeps the offsets of the pairs it finds
    // again; both orientations (the build lists a pair by the node that found it). States of
    // several writers add up.
    for (std::size_t q = 0; q < pairs.size(); ++q)
      {
        const int a = naming.index(pairs[q].first), b = naming.index(pairs[q].second);
        if (a < 0 || b < 0)
          continue;
        candidates_.push_back({{static_cast<unsigned int>(a), static_cast<unsigned int>(b)}});
        candidates_.push_back({{static_cast<unsigned int>(b), static_cast<unsigned int>(a)}});
        offset_.push_back(offsets[q]);
        offset_.push_back(offsets[q]);
      }
  }
} // namespace shard::contact
