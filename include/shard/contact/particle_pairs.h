// SPDX-License-Identifier: LGPL-2.1-or-later
/**
 * @file particle_pairs.h
 * @brief Contact type `particles`: particle against particle (spheres of radius h/2) among the
 * particles of the bodies, for the pairs without an intact bond.
 * @ingroup contact
 */
#pragma once

#include <shard/contact/interaction.h>

#include <array>
#include <vector>

namespace shard::contact
{
  /**
   * @brief Particle against particle: two spheres that overlap by delta repel each other with
   * k delta along the line of centres, k = s min(K) min(h), with the dashpot and friction of
   * the settings. The overlap a pair already had when it first met (neighbours whose bond just
   * broke in a compressed zone) is ignored, the smallest since is kept, and it is forgotten as
   * the pair separates: no energy from nothing (LS-DYNA's IGNORE of initial penetrations).
   *
   * The search keeps bonded pairs within reach as dormant: they join the candidates when their
   * bond breaks or one of their particles becomes free (wake()), so the step loop visits
   * unbonded pairs only.
   */
  class ParticlePairs : public Interaction
  {
  public:
    using Interaction::Interaction;

    void
    reset(const ContactNodes &nodes) override;

    /// 2 sqrt(m* / k) per particle with the reduced mass m/2 of two equal particles.
    double
    stable_dt(const ContactNodes &nodes) const override;

    /// Candidate and dormant pairs; the offsets of pairs found again are kept.
    void
    build(const SearchContext &context) override;

    void
    wake(const BondNews &news) override;

    void
    add_forces(const ContactNodes &nodes, unsigned int step, double dt, ForceSink &sink) override;

    void
    save(base::BinaryWriter &out) const override;

    void
    load(base::BinaryReader &in) override;

    /// The pairs with an offset, by name.
    void
    write_state(base::BinaryWriter &out, const ContactNodes &nodes, const NodeNaming &naming) const override;

    void
    read_state(base::BinaryReader &in, const ContactNodes &nodes, const std::vector<int> &where,
               const NodeNaming &naming) override;

    /// Candidate pairs (node indices).
    const std::vector<std::array<unsigned int, 2>> &
    candidates() const
    {
      return candidates_;
    }

  private:
    /// Finds the pairs within reach (finder, other), in the order of the finder, then of the
    /// other; sorts them into candidates (unbonded) and dormant pairs.
    void
    search(const SearchContext &context);

    /// The pairs within reach at the last build that were bonded.
    struct Dormant
    {
      std::vector<std::array<unsigned int, 2>> pairs;
      std::vector<unsigned char>               woken;
      std::vector<unsigned int>                offsets; // per node, into of_node
      std::vector<unsigned int>                of_node; // pair indices
    };
    std::vector<std::array<unsigned int, 2>> candidates_;
    Dormant                                  dormant_;
    /// Per candidate: the overlap the pair had when it first met (ignored, the smallest since;
    /// -1 before the first evaluation).
    std::vector<double> offset_;
  };
} // namespace shard::contact
