// SPDX-License-Identifier: LGPL-2.1-or-later
/**
 * @file bond_filter.h
 * @brief Which particle pairs are joined by an intact bond (no contact between them), kept in
 * step with the particle set's broken-bond and free-particle lists.
 * @ingroup contact
 */
#pragma once

#include <shard/contact/contact_nodes.h>

#include <array>
#include <unordered_map>
#include <utility>
#include <vector>

namespace shard::contact
{
  /// Bonds broken and particles freed since the last BondFilter::sync(), as node indices.
  struct BondNews
  {
    std::vector<std::array<unsigned int, 2>> broken;
    std::vector<unsigned int>                 freed;
  };

  /**
   * @brief The bond filter of particle contact: two particles of one body meet through contact
   * only when no intact bond joins them (one inside the other's box support, the bond not
   * broken, neither particle free).
   *
   * The particle set keeps sorted global lists of broken bonds (pairs of particle ids, global
   * DOF / 3) and free particles. sync() takes what is new in them by a set difference and keeps
   * per node its broken partners and whether it is free, so that bonded() needs no search.
   */
  class BondFilter
  {
  public:
    /// Starts afresh for the node list @p nodes (after Contact::prepare()).
    void
    reset(const ContactNodes &nodes);

    /**
     * @brief Brings the filter up to the particle set's lists @p broken (sorted pairs of
     * particle ids) and @p free (sorted particle ids); returns what is new since the last call.
     */
    BondNews
    sync(const std::vector<std::pair<unsigned long long, unsigned long long>> &broken,
         const std::vector<unsigned long long>                                &free);

    /// Whether particles @p a and @p b (node indices of @p nodes) are joined by an intact bond.
    bool
    bonded(const ContactNodes &nodes, unsigned int a, unsigned int b) const;

    /// Checkpoint at the same partition.
    void
    save(base::BinaryWriter &out) const;

    /// Restores what save() wrote, after reset().
    void
    load(base::BinaryReader &in);

  private:
    /// The lists at the last sync(): what is new since is found by a set difference.
    std::vector<std::pair<unsigned long long, unsigned long long>> seen_broken_;
    std::vector<unsigned long long>                                  seen_free_;
    /// Per node, whether its particle is free, and the nodes of its broken bonds.
    std::vector<unsigned char>             free_node_;
    std::vector<std::vector<unsigned int>> broken_partners_;
    /// Particle id (global DOF / 3) to node index, for the particle nodes.
    std::unordered_map<unsigned long long, unsigned int> node_of_particle_;
  };
} // namespace shard::contact
