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
#include <shard/contact/bond_filter.h>
#include <shard/contact/contact_nodes.h>
#include <shard/contact/interaction.h>
#include <shard/materials/material_library.h>
#include <shard/mesh/discretization.h>
#include <shard/particles/particle_set.h>

#include <array>
#include <map>
#include <memory>
#include <set>
#include <unordered_map>
#include <string>
#include <vector>

#include <functional>

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
   * Contact owns what the interactions share: the gathered node set (ContactNodes), the
   * exchange of positions and velocities, the rebuild rule with the reach of every node, the
   * bond filter (BondFilter), the contact force of the step and its work. Each interaction is
   * an Interaction object (NodeToSurface, ParticlePairs, RigidWall) with its own search,
   * forces, critical step and state; they are called in the order of declaration, so the force
   * sums keep their order.
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
     * every contact node from its owner.
     * @return the bytes this rank sent (its records, once to every other rank; base::Traffic)
     * @note Collective.
     */
    double
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

    /// Bytes of the node and segment lists and the per-node arrays on this rank (the pair lists
    /// of the interactions are not counted). Replicated today: O(contact nodes of all ranks).
    double
    memory_consumption() const;

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
      /// Per interaction: its state (Interaction::write_state(), nodes named by key).
      std::vector<std::string> interactions;
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
        io(keys), io(force), io(interactions), io(owned_keys), io(x_old);
        io(last_build), io(n_rebuilds), io(energy), io(friction_energy), io(damping_energy);
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
    /// Settings and resolved bodies of every interaction, in declaration order; fails on an
    /// unknown body or an FE-only key that names a particle body.
    std::vector<InteractionSettings>
    resolve(const mesh::Discretization &discretization, const materials::MaterialLibrary &materials,
            const particles::ParticleSet &particles, const base::PrmSource &source) const;
    /// Gathers the contact nodes and segments of all ranks (the bodies flagged in @p involved)
    /// into nodes_ and the exchange layout.
    void
    gather(const mesh::Discretization &discretization, const materials::MaterialLibrary &materials,
           const particles::ParticleSet &particles, const std::vector<bool> &converted_cells,
           const mesh::Vector &mass, const std::vector<bool> &involved);

    std::string                                names_text_;
    std::vector<std::string>                   names_;
    std::map<std::string, InteractionSettings> settings_;
    std::set<std::string>                      declared_names_;
    bool                                       declared_          = false;
    double                                     skin_              = 0;
    unsigned int                               rebuild_interval_  = 50;
    double                                     friction_velocity_ = 1e-3;
    /// The interactions, in declaration order (the force sums keep it).
    std::vector<std::unique_ptr<Interaction>> interactions_;

    MPI_Comm                  comm_ = MPI_COMM_SELF;
    ContactNodes              nodes_;
    std::vector<int>          counts_, displs_;   // per rank, in doubles (6 per node)
    std::vector<unsigned int> owned_local_dof_;   // this rank's contact nodes, local DOF
    unsigned int              owned_begin_ = 0;   // index of this rank's first node in nodes_
    std::vector<double>       force_, force_old_, x_old_;
    std::vector<Vec3>         x_build_;
    /// Per node, how far it may move before the candidates are rebuilt (m): skin/2, or more
    /// for a node fast enough to cover that in fewer than reach_steps steps.
    std::vector<double>       reach_;
    static constexpr double   reach_steps = 16;
    BondFilter                bonds_;
    const particles::ParticleSet *particles_ = nullptr;
    unsigned int                  last_build_ = 0;
    bool                          built_      = false;
    unsigned int                  n_rebuilds_ = 0;
    double energy_ = 0, friction_energy_ = 0, damping_energy_ = 0, stored_energy_ = 0, wall_force_ = 0, stable_dt_ = 1e300;
    double skin_used_ = 0;

    /// What a second prepare() (after a conversion) keeps of the contacts that go on, by global
    /// DOF: the DOFs do not change in a conversion, the node indices do.
    struct Carried
    {
      std::vector<unsigned long long> dof;          // per old node
      std::vector<double>             force;        // 3 per old node
      std::vector<std::string>        interactions; // Interaction::write_state(), names are DOFs
      std::vector<unsigned long long> owned_dof;
      std::vector<double>             x_old; // 3 per owned old node
    };
    /// The contact state before a new prepare() (empty at the first).
    Carried
    carry() const;
    /// Puts what carry() kept back onto the new node and pair lists. Without it, every spring
    /// compressed at a conversion lost its stored energy (the pair restarted with its present
    /// penetration as the entry offset): most of the showcase's 1313 J of lost contact energy.
    void
    restore(const Carried &carried);
    /// Reads the state of every interaction from @p states for the old nodes at @p where.
    void
    read_interactions(const std::vector<std::string> &states, const std::vector<int> &where,
                      const NodeNaming &naming);

    void
    build_candidates(unsigned int step, double dt);
  };
} // namespace shard::contact
