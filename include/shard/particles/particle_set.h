// SPDX-License-Identifier: LGPL-2.1-or-later
/**
 * @file particle_set.h
 * @brief Bodies discretized by particles: particles at the nodes of the body's hex mesh,
 *        their volumes, spacings and boundary data, the RK stencils and the ghost set.
 *        Subsection `E - Particles`.
 * @ingroup particles
 */
#pragma once

#include <shard/base/parameters.h>
#include <shard/mesh/discretization.h>
#include <shard/particles/spg_operator.h>

#include <algorithm>
#include <string>
#include <unordered_map>
#include <utility>
#include <vector>

namespace shard::particles
{
  /**
   * @brief The particle set (node-based scheme, formulation.md section 7): every node of a
   * converted cell is a particle whose coefficient d_K is the node's DOF triple in the one
   * distributed vector; V_I = sum of V_e / 8 over its cells, m_I = the lumped FE mass.
   *
   * prepare() writes the table rows of the owned particles (global DOF, X, V, spacing, outward
   * area vector, boundary flag, component), receives those of other ranks within two support
   * radii (point to point, chosen by all-gathered region boxes), builds the stencils of the
   * owned particles with build_local_stencils() and adds the two-hop coefficients to the ghost
   * set of the Discretization. No rank holds the table of all particles
   * (doc/manual/particles.md, "Parallel").
   */
  class ParticleSet : public base::ParameterOwner
  {
  public:
    bool
    declare_parameters(dealii::ParameterHandler &prm) override;

    void
    check_parameters(const base::PrmSource &source) const override;

    /**
     * @brief Builds the particle set from the cells flagged in @p converted_cells (by active
     * cell index): one particle per node of a converted cell, V_I = sum of V_e / 8 over its
     * converted cells. Nodes shared with intact cells are interface particles: their A rows are
     * interpolating (u_J = d_J, so the FE side sees the same nodal value) and the interface
     * faces count as boundary of the particle domain in the area vectors. Particles on the
     * faces listed in @p interpolating_faces (body name, boundary id, -1 for all faces of the
     * body) get interpolating rows too. RK supports stay within one connected component of
     * converted cells. A second call rebuilds everything (conversion during the run); the
     * bonds broken before stay broken, but their rows are left plain (built from every
     * neighbour) until rebuild_broken_rows(): SpgForce::prepare() calls it, after the consistent
     * gradient correction, whose constraint system is consistent only when every row is linearly
     * exact (a broken row, e.g. a free particle's empty row, is not).
     * @throws base::InputError if a listed body does not exist.
     * @note Collective; may widen the ghost set of @p discretization.
     */
    void
    prepare(mesh::Discretization &discretization, const std::vector<bool> &converted_cells,
            const std::vector<std::pair<std::string, int>> &interpolating_faces, const base::PrmSource &source);

    /// Names in `E - Particles/bodies` (bodies converted whole at set-up).
    std::vector<std::string>
    body_names() const
    {
      return base::split(body_names_text_, ',');
    }

    /// Whether there are particles anywhere.
    bool
    active() const
    {
      return active_;
    }

    /// Whether owned particle @p i is an interface particle (shared with intact elements).
    bool
    is_interface(unsigned int i) const
    {
      return interface_[i];
    }

    /// Connected component (of converted cells) of owned particle @p i.
    unsigned int
    component(unsigned int i) const
    {
      return component_[i];
    }

    /// Number of connected components of converted cells over all ranks.
    unsigned int
    n_components() const
    {
      return n_components_;
    }

    /// Whether body @p b is made of particles.
    bool
    is_particle_body(unsigned int b) const
    {
      return b < particle_body_.size() && particle_body_[b];
    }

    /// The local stencils (compact K numbering: owned particles first).
    const LocalStencils &
    stencils() const
    {
      return stencils_;
    }

    /// Local vector index of the first DOF of compact coefficient @p k.
    unsigned int
    local_dof(unsigned int k) const
    {
      return local_dof_[k];
    }

    /// Number of owned particles (rows I).
    unsigned int
    n_owned() const
    {
      return stencils_.n_i;
    }

    /// Number of particles over all ranks.
    unsigned long long
    n_global() const
    {
      return n_global_;
    }

    /// Rows of the particle table the last prepare() built the stencils from: this rank's
    /// particles and those of other ranks within two support radii (a guard against a table of
    /// all particles coming back; summary.json `particle_table_rows_by_rank`).
    unsigned long long
    table_rows() const
    {
      return table_rows_;
    }

    /// Reference volume of owned particle @p i.
    double
    volume(unsigned int i) const
    {
      return volume_[i];
    }

    /// Outward area vectors of the owned particles (3 each, zero inside the body).
    const std::vector<double> &
    area_vectors() const
    {
      return area_;
    }

    /// Spacing per direction of owned particle @p i.
    const Point3 &
    spacing(unsigned int i) const
    {
      return spacing_[i];
    }

    /// Support radii a_k = c h_k of owned particle @p i (m; c = `dilation`).
    Point3
    support_radius(unsigned int i) const
    {
      return rk_.support_radius(spacing_[i]);
    }

    /// Mean support radius c (h_x + h_y + h_z) / 3 of owned particle @p i (m).
    double
    mean_support_radius(unsigned int i) const
    {
      const auto &h = spacing_[i];
      return rk_.dilation * (h[0] + h[1] + h[2]) / 3.;
    }

    /// Reference position of owned particle @p i.
    const Point3 &
    position(unsigned int i) const
    {
      return position_[i];
    }

    /// Body index of owned particle @p i.
    unsigned int
    body(unsigned int i) const
    {
      return body_[i];
    }

    /// Global DOF of owned particle @p i divided by 3 (its global particle id).
    unsigned long long
    global_id(unsigned int i) const
    {
      return global_id_[i];
    }

    /**
     * @brief Overwrites the gradient values of the G stencils in place (same pattern, 3 per
     * entry), e.g. with ConsistentCorrection::corrected_gradients(); operators built on the
     * stencils see the new values.
     * @throws std::invalid_argument on a size mismatch
     */
    void
    replace_gradients(const std::vector<double> &gradients);

    /// The RK parameters (dilation, support, condition limit).
    const RkParameters &
    rk_parameters() const
    {
      return rk_;
    }

    /**
     * @brief Bytes this object keeps on this rank after prepare(): the local stencils
     * (LocalStencils::memory_consumption()) and the per-particle arrays (local DOF, volume,
     * area vector, spacing, position, body, global id; allocated capacities), the bond lists and
     * targets. The halo table of prepare() is freed at its end and not counted.
     */
    std::size_t
    memory_consumption() const;

    /// A bond between two particles, by global particle id (first < second).
    using Bond = std::pair<unsigned long long, unsigned long long>;

    /**
     * @brief Breaks the bonds @p bonds for good: their entries of A and G are set to zero and
     * every local row that held one is rebuilt from its surviving bonds (formulation.md
     * section 5: RK with the remaining neighbours, Shepard when fewer than 4 remain, the
     * identity when only the particle itself remains). Interpolating A rows stay identities.
     * Rebuilt G rows carry the plain RK gradients (the consistent correction is not re-solved;
     * doc/manual/failure.md). The particles @p free_ids (global ids) lose every bond, in
     * whichever local row it is stored. Bonds and particles this rank does not hold are skipped
     * but remembered; everything is remembered, so a rebuild by prepare() (conversion) never
     * restores them. Not collective: spread_bonds() and spread_free() bring the lists to the
     * ranks that need them.
     * @return the number of local rows rebuilt
     */
    unsigned int
    break_bonds(const std::vector<Bond> &bonds, const std::vector<unsigned long long> &free_ids = {});

    /**
     * @brief Breaks the bonds found by the tests of this rank's rows (@p found, first < second)
     * on every rank that needs them, with two point-to-point rounds: each bond goes to the
     * owners of its two particles; each owner sends the bonds new to it to the ranks that hold
     * its particle (targets()). A rank therefore knows a broken bond (a, b) exactly when it owns
     * a or b or is a target of a or b (doc/manual/failure.md "Parallel").
     * @param bytes incremented by the bytes this rank sent
     * @return the number of bonds new to this rank whose smaller id it owns (their sum over
     *         the ranks counts every new bond once)
     * @note Collective.
     */
    unsigned long long
    spread_bonds(MPI_Comm comm, const std::vector<Bond> &found, double &bytes);

    /**
     * @brief Frees the owned particles @p owned_ids (global ids) and tells the ranks that hold
     * them (targets()); breaks what the other ranks free as well.
     * @return the number of particles of @p owned_ids that were not free before
     * @note Collective.
     */
    unsigned long long
    spread_free(MPI_Comm comm, const std::vector<unsigned long long> &owned_ids, double &bytes);

    /**
     * @brief The ranks that must hear of the broken bonds and the freeing of owned particle
     * @p i: those that hold it as a ghost (its A or G entries may be there) and the owners of
     * the coefficients of its G row (their particle pairs with it are judged there by contact),
     * without this rank; sorted.
     */
    std::pair<const unsigned int *, const unsigned int *>
    targets(const unsigned int i) const
    {
      return {targets_.data() + target_offsets_[i], targets_.data() + target_offsets_[i + 1]};
    }

    /// Rows rebuilt after bonds broke use Shepard functions below this reciprocal condition
    /// number of the scaled moment matrix (or the RK limit, if larger). Unit: 1.
    void
    set_broken_condition_limit(double limit)
    {
      broken_rcond_limit_ = limit;
    }

    /// Free particles this rank knows of (global ids, sorted): its own and those of targets().
    const std::vector<unsigned long long> &
    free_particles() const
    {
      return free_;
    }

    /// Reference position of compact coefficient @p k.
    const Point3 &
    compact_position(unsigned int k) const
    {
      return compact_position_[k];
    }

    /// Rebuilds every local row that holds a broken bond again (after a new gradient
    /// correction has overwritten G). Not collective.
    void
    rebuild_broken_rows();

    /// The broken bonds and free particles as they were at the last prepare(): with them the
    /// consistent correction of the last prepare() is solved again (checkpoint).
    const std::vector<Bond> &
    bonds_at_prepare() const
    {
      return prepared_broken_;
    }

    /// Free particles at the last prepare() (see bonds_at_prepare()).
    const std::vector<unsigned long long> &
    free_at_prepare() const
    {
      return prepared_free_;
    }

    /**
     * @brief Restart: sets the broken bonds and free particles (global ids) that the next
     * prepare() builds the stencils with: those of the checkpoint with an end this rank owns.
     * That prepare() tells all targets (as restrict_to_needed()). Not collective.
     */
    void
    restore_broken(std::vector<Bond> bonds, std::vector<unsigned long long> free_ids)
    {
      std::sort(bonds.begin(), bonds.end());
      bonds.erase(std::unique(bonds.begin(), bonds.end()), bonds.end());
      std::sort(free_ids.begin(), free_ids.end());
      free_ids.erase(std::unique(free_ids.begin(), free_ids.end()), free_ids.end());
      broken_     = std::move(bonds);
      free_       = std::move(free_ids);
      restarting_ = true;
    }

    /**
     * @brief Restart, after break_bonds() with the bonds and free particles of the checkpoint
     * that have an end this rank owns: every owner tells all its targets, which break what
     * they did not know, so that each rank knows what it knew in the run (it owns an end, or
     * is a target of one; spread_bonds()). Collective.
     */
    void
    restrict_to_needed(MPI_Comm comm);

    /// The broken bonds this rank knows of (sorted): those of its own particles and of the
    /// particles it is a target of (spread_bonds()).
    const std::vector<Bond> &
    broken_bonds() const
    {
      return broken_;
    }

    /// Whether entry @p e of the G stencil (LocalStencils::g) is an intact bond.
    bool
    g_entry_intact(std::size_t e) const
    {
      return g_intact_[e] != 0;
    }

    /// Global particle id of compact coefficient @p k (rows I and J included).
    unsigned long long
    compact_id(unsigned int k) const
    {
      return compact_id_[k];
    }

    /// Number of intact bonds of owned particle @p i to other particles (G row, itself excluded).
    unsigned int
    intact_bonds(unsigned int i) const;

    /**
     * @brief The owned rows whose bonds changed since the last call (sorted; after prepare()
     * every owned row), and forgets them: only these can have lost bonds, so only these need a
     * new count of intact bonds.
     */
    std::vector<unsigned int>
    take_changed_rows();

    /// The rows take_changed_rows() would return now, kept (checkpoint).
    const std::vector<unsigned int> &
    changed_rows() const
    {
      return changed_rows_;
    }

    /// Restart at the same partition: the changed rows of a checkpoint replace the present ones.
    void
    restore_changed_rows(std::vector<unsigned int> rows)
    {
      changed_rows_ = std::move(rows);
    }

    /// The local rows of A (first) and of G (second) rebuilt by break_bonds() since the last
    /// call (sorted), and forgets them; for SpgForce::refresh_forces().
    std::pair<std::vector<unsigned int>, std::vector<unsigned int>>
    take_rebuilt_rows();

  private:
    std::string              body_names_text_;
    std::vector<std::string> body_names_;
    std::string              support_text_ = "box";
    RkParameters             rk_;
    bool                     active_   = false;

    std::vector<bool>               particle_body_;
    LocalStencils                   stencils_;
    std::vector<unsigned int>       local_dof_;
    std::vector<double>             volume_, area_;
    std::vector<Point3>             spacing_, position_;
    std::vector<unsigned int>       body_;
    std::vector<unsigned long long> global_id_;
    std::vector<bool>               interface_;
    std::vector<unsigned int>       component_;
    unsigned int                    n_components_ = 0;
    /// Per compact coefficient K: global id, reference position, support radii.
    std::vector<unsigned long long> compact_id_;
    /// Compact index by global id (built at the first break after prepare()).
    std::unordered_map<unsigned long long, unsigned int> compact_of_;
    std::vector<Point3>             compact_position_, compact_radius_;
    /// Per A row: 1 when it is an identity (interpolating) row.
    std::vector<unsigned char> a_identity_;
    /// Per entry of A and G: 1 while the bond is intact.
    std::vector<unsigned char> a_intact_, g_intact_;
    /// Column index of a stencil: for column c, the rows and entries that reference it.
    struct ColumnIndex
    {
      std::vector<unsigned int> offsets, rows, entries;
      void
      build(const Stencil &s);
    };
    /// Column indices of A and G (built at the first free particle after prepare()).
    ColumnIndex a_by_column_, g_by_column_;
    /// Owned rows whose bonds changed since take_changed_rows() was last called.
    std::vector<unsigned int> changed_rows_;
    /// Rows of A and G rebuilt since take_rebuilt_rows() was last called.
    std::vector<unsigned int> rebuilt_a_rows_, rebuilt_g_rows_;
    /// Broken bonds (global ids, sorted), kept across rebuilds.
    std::vector<Bond> broken_;
    /// broken_ and free_ at the start of the last prepare().
    std::vector<Bond>               prepared_broken_;
    std::vector<unsigned long long> prepared_free_;
    /// Free particles (global ids, sorted), kept across rebuilds.
    std::vector<unsigned long long> free_;
    /// Per compact coefficient: the rank that owns it.
    std::vector<unsigned int> compact_owner_;
    /// targets() of the owned particles (CSR by owned index).
    std::vector<unsigned int> target_offsets_, targets_;
    /// (global id, rank) pairs already told of the lists (sorted): a rebuild sends each owned
    /// particle's bonds only to its new targets.
    std::vector<std::pair<unsigned long long, unsigned int>> told_;
    /// Set by restore_broken(): the next prepare() cuts the lists to what this rank needs.
    bool restarting_ = false;
    double                          broken_rcond_limit_ = 0;
    /// Marks the entries of the local rows that hold a bond of @p bonds or a particle of
    /// @p free_ids (sorted); returns the rows of A and of G that changed.
    void
    mark_broken(const std::vector<Bond> &bonds, const std::vector<unsigned long long> &free_ids,
                std::vector<unsigned int> &a_rows, std::vector<unsigned int> &g_rows);
    /// Rebuilds the listed rows of A and G from their intact entries.
    void
    rebuild_rows(const std::vector<unsigned int> &a_rows, const std::vector<unsigned int> &g_rows);
    /// prepare(), first part: remembers the broken bonds and free particles, reads `support`
    /// and `bodies` and marks the particle bodies.
    /// @throws base::InputError (through @p source) if a listed body does not exist.
    void
    select_bodies(const mesh::Discretization &discretization, const base::PrmSource &source);
    /// prepare(): empties the stencils and the per-particle arrays.
    void
    clear_particles();
    /// prepare(): adds the two-hop coefficients to the ghost set of @p discretization and sets
    /// local_dof_; @p rows holds the particle table row of every cloud index.
    void
    add_two_hop_ghosts(mesh::Discretization &discretization, const std::vector<const double *> &rows);
    /// prepare(): the per compact coefficient arrays for rebuilding rows after bonds break, then
    /// rebuilds the rows of the bonds broken before (they stay broken across a rebuild).
    void
    set_compact_arrays(const ParticleCloud &cloud, const std::vector<const double *> &rows);
    /// prepare(): compact_owner_ and the targets() of the owned particles, from the ghost and
    /// import lists of @p discretization's partitioner and the G stencil.
    void
    set_targets(const mesh::Discretization &discretization);
    /// Sends the bonds and free particles this rank knows of each owned particle to the targets
    /// not told yet (all of them when @p everyone: a restart), and merges what arrives; returns
    /// what arrived that was new (not yet marked in the stencils). Collective.
    std::pair<std::vector<Bond>, std::vector<unsigned long long>>
    tell_targets(MPI_Comm comm, bool everyone);
    /// Marks and rebuilds the rows of bonds and free particles not seen before (break_bonds()
    /// after merging them into the lists); returns the number of rows rebuilt.
    unsigned int
    apply_broken(const std::vector<Bond> &new_bonds, const std::vector<unsigned long long> &new_free);
    /// Compact index of global id @p id, or ~0u (builds compact_of_ when needed).
    unsigned int
    compact_index(unsigned long long id);
    /// prepare(): volume, area vector, spacing, position, body, id, interface flag and component
    /// of the owned particles, cloud indices @p owned in row order.
    /// @throws base::InputError for a particle without volume.
    void
    set_owned_arrays(const std::vector<const double *> &rows, const std::vector<unsigned int> &owned);
    /// prepare(): warns (rank 0) about particles on the Shepard fallback. @note Collective.
    void
    report_fallback(MPI_Comm comm, const ParticleCloud &cloud) const;
    unsigned long long              n_global_ = 0, table_rows_ = 0;
  };
} // namespace shard::particles
