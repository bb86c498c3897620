// SPDX-License-Identifier: LGPL-2.1-or-later
#include <shard/base/binary_archive.h>
#include <shard/contact/bond_filter.h>

#include <algorithm>
#include <cmath>
#include <iterator>

namespace shard::contact
{
  void
  BondFilter::reset(const ContactNodes &nodes)
  {
    node_of_particle_.clear();
    for (unsigned int i = 0; i < nodes.size(); ++i)
      if (nodes.nodes[i].particle)
        node_of_particle_.emplace(nodes.nodes[i].dof / 3, i);
    seen_broken_.clear();
    seen_free_.clear();
    free_node_.assign(nodes.size(), 0);
    broken_partners_.assign(nodes.size(), {});
  }

  bool
  BondFilter::bonded(const ContactNodes &nodes, const unsigned int a, const unsigned int b) const
  {
    const ContactNode &p = nodes.nodes[a], &q = nodes.nodes[b];
    if (!p.particle || !q.particle || p.body != q.body || free_node_[a] || free_node_[b])
      return false;
    const auto &partners = broken_partners_[a];
    if (std::find(partners.begin(), partners.end(), b) != partners.end())
      return false;
    // A bond: one particle inside the other's (box) support.
    const auto inside = [&](const unsigned int i, const ContactNode &other) {
      for (unsigned int c = 0; c < 3; ++c)
        if (std::abs(other.X[c] - nodes.nodes[i].X[c]) >= nodes.nodes[i].support[c])
          return false;
      return true;
    };
    return inside(a, q) || inside(b, p);
  }

  BondNews
  BondFilter::sync(const std::vector<std::pair<unsigned long long, unsigned long long>> &broken,
                   const std::vector<unsigned long long>                                &free)
  {
    BondNews news;
    if (broken.size() == seen_broken_.size() && free.size() == seen_free_.size())
      return news;
    std::vector<std::pair<unsigned long long, unsigned long long>> new_bonds;
    std::vector<unsigned long long>                                  new_free;
    std::set_difference(broken.begin(), broken.end(), seen_broken_.begin(), seen_broken_.end(),
                        std::back_inserter(new_bonds));
    std::set_difference(free.begin(), free.end(), seen_free_.begin(), seen_free_.end(), std::back_inserter(new_free));
    seen_broken_ = broken;
    seen_free_   = free;
    const auto node = [&](const unsigned long long id) {
      const auto it = node_of_particle_.find(id);
      return it == node_of_particle_.end() ? ~0u : it->second;
    };
    for (const auto &[a, b] : new_bonds)
      {
        const unsigned int i = node(a), j = node(b);
        if (i == ~0u || j == ~0u)
          continue;
        broken_partners_[i].push_back(j);
        broken_partners_[j].push_back(i);
        news.broken.push_back({{i, j}});
      }
    for (const unsigned long long id : new_free)
      {
        const unsigned int i = node(id);
        if (i == ~0u)
          continue;
        free_node_[i] = 1;
        news.freed.push_back(i);
      }
    return news;
  }

  void
  BondFilter::save(base::BinaryWriter &out) const
  {
    out.put(std::string("bond filter"));
    out.put(seen_broken_);
    out.put(seen_free_);
    out.put(free_node_);
    out.put(broken_partners_);
  }

  void
  BondFilter::load(base::BinaryReader &in)
  {
    in.expect("bond filter");
    in.get(seen_broken_);
    in.get(seen_free_);
    in.get(free_node_);
    in.get(broken_partners_);
  }
} // namespace shard::contact
