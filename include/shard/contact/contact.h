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
   * Parallel layout (doc/manual/contact.md, "Parallel"): every rank keeps its own contact nodes
   * and the segments of its cells, and a halo: the nodes and segments of other ranks that can
   * meet one of its nodes before the next candidate rebuild (within the largest reach of any
   * node, the face depth and the deepest penetration, chosen by boxes around the ranks' nodes;
   * a segment's nodes come with it). Each pair is evaluated once, on the rank that owns its slave (node to
   * surface), its particle of smaller DOF (particles) or its node (rigid wall); the forces on
   * halo nodes go back to their owners at the accumulate phase. The halo is rebuilt with the
   * candidates (the rebuild rule, decided for all ranks at once) and otherwise its positions
   * and velocities are exchanged point to point each step: the traffic is that of the nodes
   * near a rank's region, not of the whole contact surface.
   */
  class Contact : public base::ParameterOwner
  {
  public:
    bool
    declare_parameters(dealii::ParameterHandler &prm) override;

    void
    check_parameters(const base::PrmSource &source) const override;

    /**
     * @brief Collects this rank's contact nodes (and tells the owners of the other nodes of its
     * surface faces), their masses and penalty stiffnesses, and its segments. The halo follows
     * at the next exchange(). Call again after a conversion (the FE surface and the particles
     * change).
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
     * @brief The exchange of step @p step (length @p dt): decides the candidate rebuild for all
     * ranks (a node has moved more than its reach since the last build, skin/2 or more for
     * fast nodes, or the rebuild interval has passed; doc/manual/contact.md). On a rebuild the
     * halo is chosen afresh (bounding boxes, records sent point to point); otherwise the
     * current positions X + @p d and velocities @p v of the halo nodes come from their owners.
     * @p d needs its ghost values (the segments' nodes of this rank's cells).
     * @return the bytes this rank sent (base::Traffic)
     * @note Collective.
     */
    double
    exchange(unsigned int step, double dt, const mesh::Vector &d, const mesh::Vector &v);

    /**
     * @brief Evaluates the pairs this rank owns (builds their candidates after a rebuild; pairs
     * whose bond broke since join them) and adds the forces on its own nodes to @p f; the
     * forces on halo nodes wait for accumulate(). Books the friction and dashpot dissipation of
     * its pairs with the step @p dt. Not collective.
     */
    ContactResult
    add_forces(unsigned int step, double dt, mesh::Vector &f);

    /**
     * @brief The accumulate phase: returns the forces on halo nodes to their owners, adds those
     * received to the owned entries of @p f, and books the contact work of this rank's nodes
     * (trapezoid over their displacement).
     * @return the bytes this rank sent (base::Traffic)
     * @note Collective.
     */
    double
    accumulate(mesh::Vector &f);

    /// Energy stored in and dissipated by the contact, -sum of the work of the contact forces
    /// on this rank's nodes (J).
    double
    energy() const
    {
      return energy_;
    }

    /// Part of energy() dissipated by friction in this rank's pairs (J).
    double
    friction_energy() const
    {
      return friction_energy_;
    }

    /// Part of energy() dissipated by the normal contact damping, `damping ratio`, in this rank's
    /// pairs (J).
    double
    damping_energy() const
    {
      return damping_energy_;
    }

    /// Energy held in the penalty springs at the last evaluation, sum of k delta^2 / 2 over this
    /// rank's pairs in contact (J). The part of energy() that returns on separation.
    double
    stored_energy() const
    {
      return stored_energy_;
    }

    /// Sum of the normal forces on the rigid walls at the last evaluation, this rank's nodes (N).
    double
    wall_force() const
    {
      return wall_force_;
    }

    /// Bytes of the node and segment lists (own and halo), the exchange lists and the per-node
    /// arrays on this rank (the pair lists of the interactions are not counted).
    double
    memory_consumption() const;

    /// Candidate rebuilds so far.
    unsigned int
    n_rebuilds() const
    {
      return n_rebuilds_;
    }

    /**
     * @brief Checkpoint: writes what this rank carries from step to step (the halo and its
     * exchange lists, candidate and dormant pair lists, penetration offsets, entry depths and
     * contact normals, positions and forces of the last step, build positions and reaches, the
     * bond news seen, counters and energies). The halo depends on the partition, so load()
     * needs the same rank count.
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
      /// Key of every contact node of this rank (own and halo, in its node order).
      std::vector<unsigned long long> keys;
      /// Contact force of the last step on this rank's nodes, 3 per owned key (N).
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
     * @brief Restart at another rank count, after prepare(): forces and positions of the last
     * step of this rank's nodes, entry depths, slaves and pair offsets from @p states (one per
     * rank that wrote them; each rank's part is the pairs it evaluated), taken over when the halo
     * is built at the next exchange; the candidate lists are built afresh then and keep the
     * offsets of the pairs they find again. @p energy is this rank's share of the contact
     * energy (J); the friction and dashpot energies of all writers go to rank 0.
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
    /// This rank's contact nodes (own particles, own nodes of its faces, and the nodes of other
    /// ranks' faces it owns, told point to point) and the segments of its cells (the bodies
    /// flagged in @p involved).
    void
    gather(const mesh::Discretization &discretization, const materials::MaterialLibrary &materials,
           const particles::ParticleSet &particles, const std::vector<bool> &converted_cells,
           const mesh::Vector &mass, const std::vector<bool> &involved);
    /// Chooses the halo at the present positions (collective): bounding boxes of the ranks' own
    /// nodes, the margins, the records sent point to point; sets nodes_, the exchange lists and
    /// carries the interactions' per-node state over to the new node list. Returns the bytes
    /// sent.
    double
    build_halo(double dt);
    /// What the two point-to-point rounds of a halo build bring (build_halo()).
    struct HaloParts
    {
      /// Segment records to keep here (4 node DOFs, stiffness, body): own segments near this
      /// rank's region and those received.
      std::vector<std::array<double, 6>> segments;
      /// Node records (static record, then x and v) by sending rank, in the sender's own order.
      std::map<unsigned int, std::vector<double>> nodes;
      /// Own nodes (indices into own_) sent to each rank, in own order.
      std::vector<std::vector<unsigned int>> sent;
      /// Bytes this rank sent.
      double bytes = 0;
    };
    /// build_halo(), part 1 (collective): the margins (max-reduced), the region boxes
    /// (all-gathered) and the two rounds: segments near a rank's boxes with requests to the
    /// owners of their nodes, then the requested nodes and the particles near a rank's boxes.
    HaloParts
    exchange_halo(double dt);
    /// build_halo(), part 2: the new node list (own and received nodes sorted by DOF, segments
    /// sorted by their node DOFs), the exchange lists of the following steps, and the
    /// interactions' per-node state carried over when the list changed.
    void
    install_halo(HaloParts &&parts);
    /// Positions and velocities of the halo nodes from their owners (the lists of the last
    /// build_halo()). Returns the bytes sent.
    double
    exchange_states();
    /// Puts this rank's own states into nodes_.state.
    void
    copy_own_states();

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

    MPI_Comm comm_ = MPI_COMM_SELF;
    /// This rank's contact nodes, sorted by DOF, and their local DOF (x component).
    std::vector<ContactNode>  own_;
    std::vector<unsigned int> owned_local_dof_;
    /// A surface face of one of this rank's cells: node DOFs (counter-clockwise from outside),
    /// their local DOFs (owned or ghost) and owner ranks, stiffness and body.
    struct OwnSegment
    {
      std::array<unsigned long long, 4> dof{};
      std::array<unsigned int, 4>       local{}, owner{};
      double                            stiffness = 0;
      unsigned int                      body      = 0;
    };
    /// Reference positions of the discretization (ghost values set): with d, the segments'
    /// current positions.
    const mesh::Vector *reference_ = nullptr;
    std::vector<OwnSegment> own_segments_;
    /// Current positions and velocities of the own nodes (6 per node).
    std::vector<double> own_state_;
    /// The displacement during exchange() (the segments' current positions).
    const mesh::Vector *d_ = nullptr;
    /// The nodes (own and halo, sorted by DOF) and segments (sorted by their nodes' DOFs) the
    /// interactions see.
    ContactNodes nodes_;
    /// Index in nodes_ of each own node.
    std::vector<unsigned int> own_index_;
    /// Per other rank: the own nodes it holds in its halo (indices into own_), and the halo
    /// nodes this rank holds of it (indices into nodes_), in the order they are sent.
    std::vector<unsigned int>              send_ranks_, recv_ranks_;
    std::vector<std::vector<unsigned int>> send_lists_, recv_lists_;
    /// Contact force of the evaluation, 3 per node of nodes_ (N).
    std::vector<double> force_;
    /// Total contact force on the own nodes, this step and the last (3 per own node), and their
    /// positions of the last step (NaN: none yet).
    std::vector<double> own_force_, own_force_old_, x_old_;
    /// Positions at the last build and reaches (per node of nodes_; the rebuild rule reads the
    /// own ones).
    std::vector<Vec3>         x_build_;
    /// Per node, how far it may move before the candidates are rebuilt (m): skin/2, or more
    /// for a node fast enough to cover that in fewer than reach_steps steps.
    std::vector<double>       reach_;
    static constexpr double   reach_steps = 16;
    BondFilter                bonds_;
    const particles::ParticleSet *particles_ = nullptr;
    unsigned int                  last_build_ = 0;
    bool                          built_      = false;
    /// The halo must be chosen at the next exchange (after prepare()); the candidates must be
    /// built at the next add_forces() (the halo was rebuilt); the critical step is to be found.
    bool         halo_stale_ = true, build_pending_ = false, stable_stale_ = true;
    unsigned int n_rebuilds_ = 0;
    double energy_ = 0, friction_energy_ = 0, damping_energy_ = 0, stored_energy_ = 0, wall_force_ = 0, stable_dt_ = 1e300;
    double skin_used_ = 0;

    /**
     * @brief Interaction states written for another node list (a conversion, a restart at
     * another rank count), read when the next halo is built: per writer, the DOF of each node of
     * its list, whether the writer owned it (only its own nodes' states count), and the states.
     */
    struct Pending
    {
      std::vector<std::vector<unsigned long long>> dofs;
      std::vector<std::vector<unsigned char>>      owned;
      std::vector<std::vector<std::string>>        interactions;
      /// Names inside the states to DOFs (identity for a conversion; node keys for a restart).
      std::function<unsigned long long(unsigned long long)> dof_of_name;
    };
    Pending pending_;
    /// Reads pending_ into the interactions (after the halo of the new node list is built).
    void
    read_pending();
    /// The interactions' states of the present node list, named by DOF (one writer): what a
    /// conversion and a change of the halo carry over to the next node list.
    Pending
    written_states() const;

    /// What a second prepare() (after a conversion) keeps of the contacts that go on, by global
    /// DOF: the DOFs do not change in a conversion, the node indices do.
    struct Carried
    {
      Pending                         states; // written_states() of the old node list
      std::vector<unsigned long long> owned_dof;
      std::vector<double>             force; // 3 per owned old node
      std::vector<double>             x_old; // 3 per owned old node
    };
    /// The contact state before a new prepare() (empty at the first).
    Carried
    carry() const;
    /// Puts what carry() kept back: forces and positions of the own nodes now, the interaction
    /// states when the halo is built. Without it, every spring compressed at a conversion lost
    /// its stored energy (the pair restarted with its present penetration as the entry offset):
    /// most of the showcase's 1313 J of lost contact energy.
    void
    restore(const Carried &carried);

    void
    build_candidates(unsigned int step, double dt);
  };
} // namespace shard::contact
