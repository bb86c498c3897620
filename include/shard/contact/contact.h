// SPDX-License-Identifier: LGPL-2.1-or-later
/**
 * @file contact.h
 * @brief Penalty contact: FE surfaces against nodes and particles, particle (debris)
 *        self-contact, rigid walls; optional Coulomb friction and normal damping. Subsection
 *        `H - Contact`.
 * @ingroup contact
 *
 * Theory, stiffness choices, time-step effect and validation: doc/manual/contact.md.
 */
#pragma once

#include <shard/base/parameters.h>
#include <shard/contact/contact_geometry.h>
#include <shard/materials/material_library.h>
#include <shard/mesh/discretization.h>
#include <shard/particles/particle_set.h>

#include <array>
#include <map>
#include <set>
#include <unordered_map>
#include <string>
#include <vector>

#include <functional>

namespace shard::base
{
  class BinaryWriter;
  class BinaryReader;
} // namespace shard::base

namespace shard::contact
{
  /// What one contact evaluation returns (this rank's share).
  struct ContactResult
  {
    /// Critical step of the penalty springs, 2 sqrt(m / k) (s).
    double stable_dt = 1e300;
  };

  /**
   * @brief Penalty contact between contact nodes (FE surface nodes and particles, at their
   * current positions X + d) and contact segments (boundary faces of intact hexahedra),
   * between particles (spheres of radius h/2, pairs without an intact bond) and against
   * rigid planes.
   *
   * Interactions (`H - Contact/interactions`), each with a `type`:
   * - `node to surface`: the nodes of `body` (surface nodes of FE, every particle of particle
   *   bodies) against the surface faces of `target` (FE); `symmetric` adds the other way;
   * - `particles`: particle against particle among the particles of `body` (comma list), so
   *   debris of one body and particles of different bodies meet;
   * - `rigid wall`: the nodes of `body` against the plane through `wall point` with normal
   *   `wall normal` (towards the body).
   *
   * Parallel layout (doc/manual/contact.md): the contact nodes of all ranks are gathered at
   * every step in the exchange phase, so every rank evaluates every pair and adds the forces of
   * its own nodes. No pair is split between ranks and the forces do not depend on the
   * partition. The memory and traffic are O(contact nodes) per rank and step, fine up to a few
   * 10^5 contact nodes; a scalable import of remote candidates is issue 8.
   */
  class Contact : public base::ParameterOwner
  {
  public:
    bool
    declare_parameters(dealii::ParameterHandler &prm) override;

    void
    check_parameters(const base::PrmSource &source) const override;

    /**
     * @brief Collects the contact nodes and segments of all ranks, their masses and penalty
     * stiffnesses. Call again after a conversion (the FE surface and the particles change).
     * @param mass lumped mass (ghost values not needed)
     * @param converted_cells flags by active cell index (converted cells have no segments)
     * @note Collective.
     */
    void
    prepare(const mesh::Discretization &discretization, const materials::MaterialLibrary &materials,
            const particles::ParticleSet &particles, const std::vector<bool> &converted_cells,
            const mesh::Vector &mass, const base::PrmSource &source);

    /// Whether any interaction is defined.
    bool
    active() const
    {
      return !interactions_.empty();
    }

    /**
     * @brief The exchange: gathers the current positions X + d and the velocities @p v of
     * every contact node from its owner. @note Collective.
     */
    void
    exchange(const mesh::Vector &d, const mesh::Vector &v);

    /**
     * @brief Adds the penalty, damping and friction forces of every contact pair to the owned entries of
     * @p f; rebuilds the candidate lists when a node has moved more than its reach since the
     * last build (skin/2, more for fast nodes; doc/manual/contact.md) or the rebuild interval
     * has passed. Pairs whose bond broke since join the candidates. Accumulates the contact
     * work and, with the step @p dt, the friction and dashpot dissipation. Not collective (every rank has
     * every position).
     */
    ContactResult
    add_forces(unsigned int step, double dt, mesh::Vector &f);

    /// Energy stored in and dissipated by the contact, -sum of the work of the contact forces
    /// on this rank's nodes (J).
    double
    energy() const
    {
      return energy_;
    }

    /// Part of energy() dissipated by friction (J, counted on rank 0).
    double
    friction_energy() const
    {
      return friction_energy_;
    }

    /// Part of energy() dissipated by the normal contact damping, `damping ratio` (J, counted on
    /// rank 0).
    double
    damping_energy() const
    {
      return damping_energy_;
    }

    /// Energy held in the penalty springs at the last evaluation, sum of k delta^2 / 2 over the
    /// pairs in contact (J, counted on rank 0). The part of energy() that returns on separation.
    double
    stored_energy() const
    {
      return stored_energy_;
    }

    /// Sum of the normal forces on the rigid walls at the last evaluation (N, every rank).
    double
    wall_force() const
    {
      return wall_force_;
    }

    /// Candidate rebuilds so far.
    unsigned int
    n_rebuilds() const
    {
      return n_rebuilds_;
    }

    /**
     * @brief Checkpoint: writes what this rank carries from step to step (candidate and
     * dormant pair lists, penetration offsets, entry depths and contact normals, positions and forces of the
     * last step, build positions and reaches, the bond news seen, counters and energies).
     * The node order depends on the partition, so load() needs the same rank count.
     */
    void
    save(base::BinaryWriter &out) const;

    /**
     * @brief Restores what save() wrote, after prepare() at the same rank count and partition.
     * @throws std::runtime_error when the data do not fit this contact set.
     */
    void
    load(base::BinaryReader &in);

    /**
     * @brief The contact state in a form that does not depend on the partition: nodes by a
     * key (the caller's key of a global DOF / 3), for a restart at another rank count.
     */
    struct PortableState
    {
      /// Key of every contact node (replicated part, in this rank's node order).
      std::vector<unsigned long long> keys;
      /// Contact force of the last step, 3 per node (N).
      std::vector<double> force;
      /// Per interaction: entry depth per node (m; -1 none) and the slaves of the last step.
      std::vector<std::vector<double>>             entry_depth;
      /// Per interaction: penetration of the last step per node (m; 0 out of contact).
      std::vector<std::vector<double>> penetration;
      /// Per interaction, 4 per node: keys + 1 of the nodes of the segment a slave was in
      /// contact with at the last step (0 for none).
      std::vector<std::vector<unsigned long long>> segment;
      std::vector<std::vector<unsigned long long>> previous_slaves;
      /// Per interaction, 3 per node: the contact normal of the last step (0 out of contact).
      std::vector<std::vector<double>> contact_normal;
      /// Per interaction: particle pairs (keys) with the overlap offset they keep (m).
      std::vector<std::vector<std::pair<unsigned long long, unsigned long long>>> pairs;
      std::vector<std::vector<double>>                                            offsets;
      /// This rank's nodes: keys and positions of the last step (3 per node).
      std::vector<unsigned long long> owned_keys;
      std::vector<double>             x_old;
      /// Step of the last build, rebuilds so far, energy of this rank, friction and dashpot energy (J).
      unsigned int last_build = 0, n_rebuilds = 0;
      double       energy = 0, friction_energy = 0, damping_energy = 0;

      /// One field list for writing and reading: @p io(x) for every member.
      template <typename IO>
      void
      serialize(IO &&io)
      {
        io(keys), io(force), io(entry_depth), io(previous_slaves), io(pairs), io(offsets), io(owned_keys);
        io(x_old), io(last_build), io(n_rebuilds), io(energy), io(friction_energy), io(damping_energy);
        io(contact_normal);
        io(penetration), io(segment);
      }
    };

    /// The state of this rank as a PortableState; @p key_of_node maps global DOF / 3 to a key.
    PortableState
    portable_state(const std::function<unsigned long long(unsigned long long)> &key_of_node) const;

    /**
     * @brief Restart at another rank count, after prepare(): forces, entry depths, slaves and
     * pair offsets from @p states (one per rank that wrote them; replicated parts from the
     * first), positions of the last step of this rank's nodes from whichever rank had them;
     * the candidate lists are built afresh at the next step and keep the offsets of the pairs
     * they find again. @p energy is this rank's share of the contact energy (J).
     * @p node_of_key maps a key back to global DOF / 3.
     */
    void
    restore_portable(const std::vector<PortableState>                              &states,
                     const std::function<unsigned long long(unsigned long long)> &node_of_key, double energy);

  private:
    enum class Type
    {
      node_to_surface,
      particles,
      rigid_wall
    };
    struct Interaction
    {
      std::string type_text = "node to surface";
      std::string body_text, target;
      bool        symmetric   = false;
      double      penalty     = 0.1;
      double      friction    = 0;
      double      damping     = 0;
      std::string wall_point  = "0, 0, 0";
      std::string wall_normal = "0, 0, 1";
      // Resolved.
      Type                 type = Type::node_to_surface;
      std::vector<unsigned int> bodies;
      unsigned int         target_body = 0;
      Vec3                 point{}, normal{};
    };
    /// A contact node: one per contact DOF triple on any rank.
    struct Node
    {
      unsigned long long dof = 0; // global DOF of the x component
      Vec3               X{};
      /// Support radii of a particle's RK functions (a bond reaches that far), 0 for FE nodes.
      Vec3               support{};
      double             mass = 0, radius = 0, bulk = 0, spacing = 0;
      unsigned int       body = 0;
      bool               particle = false;
    };
    /// A boundary face of an intact hex: four contact node indices, counter-clockwise seen
    /// from outside, and its penalty stiffness.
    struct Segment
    {
      std::array<unsigned int, 4> node{};
      double                      stiffness = 0;
      unsigned int                body      = 0;
    };

    std::string                        names_text_;
    std::vector<std::string>           names_;
    std::map<std::string, Interaction> settings_;
    std::set<std::string>              declared_names_;
    bool                               declared_         = false;
    double                             skin_             = 0;
    unsigned int                       rebuild_interval_ = 50;
    double                             friction_velocity_ = 1e-3;
    std::vector<Interaction>           interactions_;

    MPI_Comm                  comm_ = MPI_COMM_SELF;
    std::vector<Node>         nodes_;
    std::vector<Segment>      segments_;
    std::vector<int>          counts_, displs_;   // per rank, in doubles (6 per node)
    std::vector<unsigned int> owned_local_dof_;   // this rank's contact nodes, local DOF
    unsigned int              owned_begin_ = 0;   // index of this rank's first node in nodes_
    std::vector<double>       state_;             // x (3) and v (3) per node
    std::vector<double>       force_, force_old_, x_old_;
    std::vector<Vec3>         x_build_;
    /// Per node, how far it may move before the candidates are rebuilt (m): skin/2, or more
    /// for a node fast enough to cover that in fewer than reach_steps steps.
    std::vector<double>       reach_;
    static constexpr double   reach_steps = 16;
    /// The broken-bond and free-particle lists (sorted) at the last sync_bonds(): what is new
    /// since is found by a set difference.
    std::vector<std::pair<unsigned long long, unsigned long long>> seen_broken_;
    std::vector<unsigned long long>                                  seen_free_;
    /// Per node, whether its particle is free, and the nodes of its broken bonds (both kept by
    /// sync_bonds(), so that bonded() needs no search in the global lists).
    std::vector<unsigned char>             free_node_;
    std::vector<std::vector<unsigned int>> broken_partners_;
    /// Particle id (global DOF / 3) to contact node index, for the particle nodes.
    std::unordered_map<unsigned long long, unsigned int> node_of_particle_;
    const particles::ParticleSet *particles_ = nullptr;
    dealii::types::global_dof_index n_dofs_ = 0;
    /// Candidates per interaction: (node, segment), (node, node) or (node).
    std::vector<std::vector<std::array<unsigned int, 2>>> candidates_;
    /// Per particles interaction: the pairs within reach at the last build that were bonded
    /// (no contact). A pair moves to the candidates when its bond breaks or one of its
    /// particles becomes free, so the step loop visits unbonded pairs only.
    struct Dormant
    {
      std::vector<std::array<unsigned int, 2>>             pairs;
      std::vector<unsigned char>                           woken;
      std::vector<unsigned int>                            offsets; // per node, into of_node
      std::vector<unsigned int>                            of_node; // pair indices
    };
    std::vector<Dormant> dormant_;
    /// Per particle-contact candidate: the overlap the pair had when it first met (ignored,
    /// the smallest since; -1 before the first evaluation).
    std::vector<std::vector<double>> offset_;
    /// Per node-to-surface interaction and node: the penetration a slave in contact had when
    /// its contact began (ignored, the smallest since); -1 out of contact.
    std::vector<std::vector<double>> entry_depth_;
    /// Per node-to-surface interaction and node: the penetration -gap of a slave in contact at
    /// the last step (m), 0 out of contact. A slave in contact is followed to that depth plus
    /// the face spacing (the contact history), so a fast impact does not push it through.
    std::vector<std::vector<double>> penetration_;
    /// Per node-to-surface interaction and node: the segment a slave was in contact with at the
    /// last step, -1 out of contact or unknown (after a conversion or a restart at another rank
    /// count). A slave that moves on to another segment keeps its spring's penetration.
    std::vector<std::vector<int>> segment_;
    /// Per interaction: whether the warning of a spring pressed more than half the face spacing
    /// was given (once per interaction).
    std::vector<bool> warned_deep_;
    /// Per node-to-surface interaction: the slaves in contact at the last step.
    std::vector<std::vector<unsigned int>> previous_slaves_;
    /// Per node-to-surface interaction, 3 per node: the unit normal of the face a slave was in
    /// contact with at the last step, (0, 0, 0) out of contact. A slave whose contact turns
    /// (cosine below corner_cosine) is checked against the nearest surface (outside_).
    std::vector<std::vector<double>> contact_normal_;
    /// Cosine of the turn of the contact normal in one step above which the nearest-surface
    /// test applies: a face of another direction (a corner of the target; the sides of a
    /// 16-sided cylinder differ by 22.5 degrees, cosine 0.92), not the same face turning.
    static constexpr double corner_cosine = 0.99;
    /// Work space: per node the index of its kept hit, -1 for none.
    std::vector<int> best_;
    /// Work space: per node the smallest gap >= 0 of a face it lies outside of (its projection
    /// on the face) in this step (m); 1e300 for none. A slave outside a face by less than it
    /// penetrates its kept face is not in contact (the nearest surface decides).
    std::vector<double> outside_;
    unsigned int                                          last_build_ = 0;
    bool                                                  built_      = false;
    unsigned int                                          n_rebuilds_ = 0;
    double energy_ = 0, friction_energy_ = 0, damping_energy_ = 0, stored_energy_ = 0, wall_force_ = 0, stable_dt_ = 1e300;
    double skin_used_ = 0;

    /// What a second prepare() (after a conversion) keeps of the contacts that go on, by global
    /// DOF: the DOFs do not change in a conversion, the node indices do.
    struct Carried
    {
      std::size_t                                      n_interactions = 0;
      std::vector<unsigned long long>                  dof;   // per old node
      std::vector<double>                              force; // 3 per old node
      std::vector<std::vector<double>>                 entry_depth, penetration, contact_normal;
      std::vector<std::vector<std::array<unsigned long long, 4>>> segment; // segment_dofs(), 0: none
      std::vector<std::vector<unsigned long long>>     previous_slaves;
      std::vector<std::vector<std::array<unsigned long long, 2>>> pairs;
      std::vector<std::vector<double>>                 offsets;
      std::vector<unsigned long long>                  owned_dof;
      std::vector<double>                              x_old; // 3 per owned old node
    };
    /// The DOFs + 1 of the four nodes of segment @p g, sorted: a name of the segment that does
    /// not depend on the segment order (which changes at a conversion).
    std::array<unsigned long long, 4>
    segment_dofs(unsigned int g) const;
    /// The contact state before a new prepare() (empty at the first).
    Carried
    carry() const;
    /// Puts what carry() kept back onto the new node and pair lists. Without it, every spring
    /// compressed at a conversion lost its stored energy (the pair restarted with its present
    /// penetration as the entry offset): most of the showcase's 1313 J of lost contact energy.
    void
    restore(const Carried &carried);

    void
    build_candidates(unsigned int step, double dt);
    /// The mean plane of a segment: a point with (x - centre) . normal above half_width, or
    /// below -half_width - depth, hits none of its triangles (usable: all four face normal).
    struct Plane
    {
      Vec3   centre{}, normal{};
      double half_width = 0;
      bool   usable     = false;
      /// Square of the radius around the centre (the mean of the four nodes, always set)
      /// beyond which no point hits the segment at depth 0: (1.01 R)^2, R the largest node
      /// distance; a point hits within depth d only inside sqrt(sphere2 + d^2) (a hit projects
      /// into a triangle with the centre as a corner, and the gap is normal to it).
      double sphere2 = 0;
    };
    std::vector<Plane>        planes_;
    std::vector<unsigned int> plane_stamp_; // step at which planes_[g] was computed
    static Plane
    mean_plane(const std::array<Vec3, 4> &x);
    /// Centre of a segment and its unit normal from the diagonals; returns the length of the
    /// diagonals' cross product (0 for a degenerate segment, whose normal is then not unit).
    static double
    segment_frame(const std::array<Vec3, 4> &x, Vec3 &centre, Vec3 &normal);
    /// Whether particles @p a and @p b (node indices) are joined by an intact bond.
    bool
    bonded(unsigned int a, unsigned int b) const;
    /// Bonds broken and particles freed since the last call, as node indices.
    struct BondNews
    {
      std::vector<std::array<unsigned int, 2>> broken;
      std::vector<unsigned int>                freed;
    };
    /// Brings free_node_ and broken_partners_ up to the particle set's lists and returns what
    /// is new since the last call.
    BondNews
    sync_bonds();
    /// Moves the dormant pairs of the bonds in @p news (broken, or a particle freed) to the
    /// candidates.
    void
    wake_broken_pairs(const BondNews &news);
  };
} // namespace shard::contact
