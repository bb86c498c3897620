// SPDX-License-Identifier: LGPL-2.1-or-later
/**
 * @file interaction.h
 * @brief One contact interaction of `H - Contact/interactions`: its settings, the base class
 * of the three types (NodeToSurface, ParticlePairs, RigidWall) with their search, forces and
 * serialization, and the force sink they add to.
 * @ingroup contact
 *
 * Pure C++17 (no deal.II headers). Contact (contact.h) owns the node set, the bond filter and
 * the interactions, and calls them in the order of declaration, so that the force sums keep
 * their order. Theory: doc/manual/contact.md.
 */
#pragma once

#include <shard/contact/bond_filter.h>
#include <shard/contact/contact_nodes.h>

#include <algorithm>
#include <cmath>
#include <functional>
#include <memory>
#include <string>
#include <utility>
#include <vector>

namespace shard::contact
{
  /// The settings of one interaction (subsection `H - Contact/<name>`) and what prepare()
  /// resolves from them.
  struct InteractionSettings
  {
    std::string name;
    std::string type_text = "node to surface";
    std::string body_text, target;
    bool        symmetric   = false;
    double      penalty     = 0.1;
    double      friction    = 0;
    double      damping     = 0;
    std::string wall_point  = "0, 0, 0";
    std::string wall_normal = "0, 0, 1";
    // Resolved.
    /// Body indices of `body`.
    std::vector<unsigned int> bodies;
    /// node to surface: body index of `target`, and whether its material is rigid.
    unsigned int target_body  = 0;
    bool         rigid_target = false;
    /// rigid wall: a point of the plane (m) and its unit normal.
    Vec3 point{}, normal{};
  };

  /// What every interaction's candidate search sees: the node set, the positions at the build
  /// and how far each node may move before the next build.
  struct SearchContext
  {
    const ContactNodes &nodes;
    /// Positions at this build (m).
    const std::vector<Vec3> &x;
    /// Per node, how far it may move until the next build (m): half the skin, or what it
    /// covers in Contact's reach_steps steps at its present speed if more.
    const std::vector<double> &reach;
    /// Half the skin (m): the reach of a slow node.
    double base = 0;
    /// Largest contact sphere radius of any node (m).
    double largest_radius = 0;
    /// The bond filter (particle pairs: bonded pairs are dormant).
    const BondFilter &bonds;
  };

  /**
   * @brief Where the interactions of one evaluation put their forces: the contact force per
   * node (3 per node, N) and the power and energy sums of the step, in the order they are
   * added.
   */
  class ForceSink
  {
  public:
    /// @p force: 3 per node, zeroed by the caller; @p friction_velocity: the regularization
    /// speed of Coulomb friction (m/s).
    ForceSink(std::vector<double> &force, const double friction_velocity)
      : force_(force)
      , friction_velocity_(friction_velocity)
    {}

    /// Adds @p w @p g to the force of node @p i.
    void
    add(const unsigned int i, const Vec3 &g, const double w)
    {
      for (unsigned int c = 0; c < 3; ++c)
        force_[3 * i + c] += w * g[c];
    }

    /// Coulomb friction for the relative velocity @p vr of a pair pressed by @p fn along
    /// @p normal, coefficient @p mu: added to @p force, its power booked as dissipation.
    void
    add_friction(const Vec3 &vr, const Vec3 &normal, const double fn, const double mu, Vec3 &force)
    {
      const Vec3 ft = coulomb_friction(vr, normal, fn, mu, friction_velocity_);
      friction_power -= ft[0] * vr[0] + ft[1] * vr[1] + ft[2] * vr[2];
      for (unsigned int c = 0; c < 3; ++c)
        force[c] += ft[c];
    }

    /// Normal force of a spring @p fn = k g with the dashpot of ratio @p zeta for reduced mass
    /// @p m and normal approach speed @p vn (< 0 approaching): max(0, fn - c vn),
    /// c = 2 zeta sqrt(k m). The dashpot's power is booked as dissipation (it is >= 0, also
    /// where the clipping acts).
    double
    damped_normal(const double fn, const double k, const double m, const double vn, const double zeta)
    {
      if (!(zeta > 0) || !(m > 0))
        return fn;
      const double total = std::max(0., fn - 2. * zeta * std::sqrt(k * m) * vn);
      damping_power -= (total - fn) * vn;
      return total;
    }

    /// Power dissipated by friction and by the normal dashpots (W), energy held in the penalty
    /// springs at this configuration (J), sum of the normal forces on rigid walls (N).
    double friction_power = 0, damping_power = 0, stored = 0, wall_force = 0;

  private:
    std::vector<double> &force_;
    double               friction_velocity_;
  };

  /**
   * @brief One contact interaction: its candidate search, its forces and its state from step to
   * step (with the serializations that carry it over a checkpoint, a conversion and a restart
   * at another rank count).
   */
  class Interaction
  {
  public:
    explicit Interaction(InteractionSettings settings)
      : settings_(std::move(settings))
    {}

    virtual ~Interaction() = default;

    /// The settings.
    const InteractionSettings &
    settings() const
    {
      return settings_;
    }

    /// Sizes the per-node state for a new node list (after Contact::prepare() gathered it).
    virtual void
    reset(const ContactNodes &nodes) = 0;

    /// Critical step of the stiffest penalty spring this interaction can make (s), over the
    /// nodes and segments of @p nodes (the smallest over the ranks is the step: every node and
    /// segment is on its owner's list).
    virtual double
    stable_dt(const ContactNodes &nodes) const = 0;

    /// How much deeper than the face spacing a candidate search reaches (m): the deepest
    /// penetration a slave is followed to (node to surface), 0 for the others. The halo margin.
    virtual double
    search_depth() const
    {
      return 0.;
    }

    /// The largest value over all ranks of what is passed (Contact sets the reduction; the
    /// identity on one rank): a stable step that needs the stiffest segment of every rank.
    void
    set_global_max(std::function<double(double)> global_max)
    {
      global_max_ = std::move(global_max);
    }

    /// Builds the candidate lists from the positions of @p context.
    virtual void
    build(const SearchContext &context) = 0;

    /// Bonds broke or particles were freed since the last step and no rebuild took place.
    virtual void
    wake(const BondNews &)
    {}

    /// Adds the forces of the candidates in contact at step @p step (length @p dt) to @p sink.
    virtual void
    add_forces(const ContactNodes &nodes, unsigned int step, double dt, ForceSink &sink) = 0;

    /// Checkpoint at the same partition: everything carried from step to step.
    virtual void
    save(base::BinaryWriter &out) const = 0;

    /// Restores what save() wrote, after reset() for the same node list.
    virtual void
    load(base::BinaryReader &in) = 0;

    /**
     * @brief The state that goes on with another node list (a conversion or a restart at
     * another rank count): per node in this list's order, and nodes inside lists by
     * @p naming.name.
     */
    virtual void
    write_state(base::BinaryWriter &out, const ContactNodes &nodes, const NodeNaming &naming) const = 0;

    /**
     * @brief Reads what write_state() wrote, after reset(): @p where gives the new index of
     * every node of the writing list (-1 for a node that is gone or not this rank's to
     * evaluate); names are resolved by @p naming.index. Several states (of several writing
     * ranks) may be read one after the other: they add up. The candidates are built afresh at
     * the next step.
     */
    virtual void
    read_state(base::BinaryReader &in, const ContactNodes &nodes, const std::vector<int> &where,
               const NodeNaming &naming) = 0;

    /// Takes the once-only notices already given by @p before (same settings), so that a new
    /// prepare() does not repeat them.
    virtual void
    keep_notices(const Interaction &)
    {}

    /// Whether this rank prints the once-only warnings (Contact sets it on rank 0 only).
    void
    set_print_notices(const bool on)
    {
      print_notices_ = on;
    }

  protected:
    /// Central differences with a dashpot of ratio zeta allow dt <= (2 / omega) (sqrt(1 +
    /// zeta^2) - zeta): the factor of 2 / omega.
    double
    damped_factor() const
    {
      return std::sqrt(1. + settings_.damping * settings_.damping) - settings_.damping;
    }

    /// The smallest critical step of the node springs k = s K h of the member nodes,
    /// 2 sqrt(m* / k) with m* = @p mass_fraction m (1/2 for two equal masses, 1 against a wall).
    double
    node_spring_dt(const ContactNodes &nodes, const double mass_fraction) const
    {
      const double damped = damped_factor();
      double       dt     = 1e300;
      for (const auto &n : nodes.nodes)
        if (std::count(settings_.bodies.begin(), settings_.bodies.end(), n.body) && n.mass > 0)
          {
            const double k = settings_.penalty * n.bulk * n.spacing;
            const double m = mass_fraction * n.mass;
            if (k > 0)
              dt = std::min(dt, damped * 2. * std::sqrt(m / k));
          }
      return dt;
    }

    InteractionSettings settings_;
    bool                print_notices_ = true;
    std::function<double(double)> global_max_ = [](const double x) { return x; };
  };

  /// The interaction of the type `settings.type_text` (node to surface, particles, rigid wall).
  std::unique_ptr<Interaction>
  make_interaction(const InteractionSettings &settings);
} // namespace shard::contact
