// SPDX-License-Identifier: LGPL-2.1-or-later
/**
 * @file rigid_wall.h
 * @brief Contact type `rigid wall`: the nodes of the bodies against a fixed plane.
 * @ingroup contact
 */
#pragma once

#include <shard/contact/interaction.h>

#include <array>
#include <vector>

namespace shard::contact
{
  /**
   * @brief The nodes of `body` against the plane through `wall point` with unit normal
   * `wall normal` (towards the body): a node below the plane by g gets the spring force
   * k g along the normal, k = s K h (s penalty scale, K and h of the node), with the dashpot
   * and friction of the settings. The wall takes the reactions (history column
   * contact_wall_force).
   */
  class RigidWall : public Interaction
  {
  public:
    using Interaction::Interaction;

    void
    reset(const ContactNodes &nodes) override;

    /// 2 sqrt(m / k) with the node's own mass (the wall does not move), for the damping ratio.
    double
    stable_dt(const ContactNodes &nodes) const override;

    /// The member nodes that can reach the plane before the next build.
    void
    build(const SearchContext &context) override;

    void
    add_forces(const ContactNodes &nodes, unsigned int step, double dt, ForceSink &sink) override;

    void
    save(base::BinaryWriter &out) const override;

    void
    load(base::BinaryReader &in) override;

    /// Nothing: the candidates are built afresh.
    void
    write_state(base::BinaryWriter &out, const ContactNodes &nodes, const NodeNaming &naming) const override;

    void
    read_state(base::BinaryReader &in, const ContactNodes &nodes, const std::vector<int> &where,
               const NodeNaming &naming) override;

  private:
    /// Candidate nodes.
    std::vector<unsigned int> candidates_;
  };
} // namespace shard::contact
