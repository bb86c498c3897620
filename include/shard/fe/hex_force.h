// SPDX-License-Identifier: LGPL-2.1-or-later
/**
 * @file hex_force.h
 * @brief Internal force of the active hexahedra: uniform-strain (one-point, mean-dilatation)
 *        element with Flanagan-Belytschko stiffness hourglass control and a Hughes-Winget
 *        objective stress update. Subsection `D - Finite elements`.
 * @ingroup fe
 */
#pragma once

#include <shard/base/instability.h>
#include <shard/base/keyed_records.h>
#include <shard/base/parameters.h>
#include <shard/materials/material_library.h>
#include <shard/materials/point_states.h>
#include <shard/mesh/discretization.h>

#include <stdexcept>
#include <string>
#include <vector>

namespace shard::fe
{
  /// What one force evaluation returns besides the force.
  struct ForceResult
  {
    /// Smallest element time step L_e / c_e of this evaluation (s).
    double stable_dt = 1e300;
    /// Increment of the stress work sum over elements of V sigma : D dt (J).
    double internal_energy = 0.;
    /// Increment of the hourglass energy (J).
    double hourglass_energy = 0.;
  };

  /**
   * @brief Owns the locally owned hexahedra, their stress, hourglass and material history,
   * and computes their nodal forces.
   *
   * Elements are sorted by material so that each material is called on contiguous batches.
   */
  class HexForce : public base::ParameterOwner
  {
  public:
    bool
    declare_parameters(dealii::ParameterHandler &prm) override;

    void
    check_parameters(const base::PrmSource &source) const override;

    /**
     * @brief Builds the element arrays from the locally owned cells, except those flagged in
     * @p converted_cells (by active cell index; cells converted to particles).
     */
    void
    prepare(const mesh::Discretization &discretization, const materials::MaterialLibrary &library,
            const std::vector<bool> &converted_cells = {});

    /**
     * @brief Adds rho0 V0 / 8 of every owned cell, converted or not, to its nodes (all three
     * components): the node-based conversion keeps the FE lumped mass, so a converted cell's
     * mass stays on the same nodes. Ghost entries are summed; call compress(add) afterwards.
     */
    void
    add_lumped_mass(mesh::Vector &mass) const;

    /**
     * @brief Removes the local elements @p elements (converted to particles), keeping stress,
     * hourglass forces and history of the others.
     */
    void
    remove_elements(const std::vector<unsigned int> &elements);

    /**
     * @brief Rewrites the stored local node indices after the ghost set changed: global index
     * through @p old_partitioner, local index through @p new_partitioner.
     */
    void
    relocalize(const dealii::Utilities::MPI::Partitioner &old_partitioner,
               const dealii::Utilities::MPI::Partitioner &new_partitioner);

    /// Smallest L_e / c of the undeformed elements with the initial wave speed (s). @note Collective.
    double
    initial_stable_dt() const;

    /**
     * @brief Adds the internal nodal forces at the end of the step into @p f (owned and ghost
     * entries; call compress(add) afterwards) and updates stress and history.
     *
     * Runs on the threads of the rank (base::n_threads()): blocks of consecutive batches of 64
     * elements of one material, colour by colour, so that the blocks running at the same time
     * share no node. The force at a node is summed colour by colour and within a block in
     * element order, and
     * the energies are summed per batch and then in batch order: the same bits for any thread
     * count. If elements fail, the exception of the lowest failing batch is thrown.
     *
     * @param[in] d displacement at the end of the step, ghost values set
     * @param[in] v velocity of the step (mid-step), ghost values set
     * @param[in] dt step size
     * @param[in] step step number, for diagnostics
     * @throws Instability for an inverted element or a non-finite stress.
     *
     * @note A long compute kernel on purpose (about 210 lines, one of the two functions of
     * source/ above the 150-line limit of issue 27; doc/manual/architecture.md, "Long
     * functions"): one loop does an element's kinematics, stress update and assembly, which
     * must keep its summation order (the same bits for any thread count) and vectorizes over
     * the batch as one unit; split into calls, the order and the vectorization are at stake.
     */
    ForceResult
    add_internal_forces(const mesh::Vector &d, const mesh::Vector &v, double dt, unsigned int step,
                        mesh::Vector &f);

    /// Number of locally owned elements.
    unsigned int
    n_local_elements() const
    {
      return static_cast<unsigned int>(cell_index_.size());
    }

    /// Active cell index of local element @p e.
    unsigned int
    cell_index(unsigned int e) const
    {
      return cell_index_[e];
    }

    /// Coarse cell id of local element @p e (its index in the merged mesh, the same at any rank count).
    std::uint64_t
    cell_id(unsigned int e) const
    {
      return cell_id_[e];
    }

    /// Local element index of the active cell @p cell_index, or -1 if the cell is not owned here.
    int
    element_of_cell(unsigned int cell_index) const
    {
      return cell_index < element_of_cell_.size() ? element_of_cell_[cell_index] : -1;
    }

    /// Cauchy stress of local element @p e, 6 components.
    const double *
    stress(unsigned int e) const
    {
      return &stress_[6 * e];
    }

    /// History slot @p name of local element @p e, or 0 if its material has none.
    double
    state_value(unsigned int e, const std::string &name) const;

    /// Body index of local element @p e.
    unsigned int
    body(unsigned int e) const
    {
      return body_[e];
    }

    /// Local index of the first DOF of vertex @p a (deal.II order) of local element @p e.
    unsigned int
    node(unsigned int e, unsigned int a) const
    {
      return nodes_[8 * e + a];
    }

    /// Reference volume of local element @p e (m^3).
    double
    reference_volume(unsigned int e) const
    {
      return volume0_[e];
    }

    /// Time step L_e / c_e of local element @p e at the last force evaluation (s).
    double
    element_stable_dt(unsigned int e) const
    {
      return element_dt_[e];
    }

    /// History slots of local element @p e (material().state_slot_names() order).
    const double *
    state(unsigned int e) const
    {
      return points_.state(e);
    }

    /**
     * @brief The checkpoint of every local element, by coarse cell id (independent of the
     * partition): stress (6), bulk viscosity q, hourglass forces (12), then the history slots.
     */
    base::KeyedRecords
    portable_state() const
    {
      base::KeyedRecords out;
      std::vector<double> r;
      for (unsigned int e = 0; e < n_local_elements(); ++e)
        {
          r.assign(stress_.begin() + 6 * e, stress_.begin() + 6 * e + 6);
          r.push_back(q_[e]);
          r.insert(r.end(), hourglass_.begin() + 12 * e, hourglass_.begin() + 12 * e + 12);
          r.insert(r.end(), state(e), state(e) + points_.n_slots(e));
          out.add(cell_id_[e], r.data(), r.data() + r.size());
        }
      return out;
    }

    /**
     * @brief Restart: every local element takes what portable_state() wrote for its cell, on
     * whichever rank that was.
     * @throws std::runtime_error when a cell is missing or has another number of values
     */
    void
    restore_portable(const base::KeyedLookup &saved)
    {
      for (unsigned int e = 0; e < n_local_elements(); ++e)
        {
          const std::string what = "element of cell " + std::to_string(cell_id_[e]);
          const auto        r    = saved.find(cell_id_[e], what);
          if (r.size != 19 + points_.n_slots(e))
            throw std::runtime_error(what + " has another number of history values");
          std::copy(r.values, r.values + 6, stress_.begin() + 6 * e);
          q_[e] = r.values[6];
          std::copy(r.values + 7, r.values + 19, hourglass_.begin() + 12 * e);
          std::copy(r.values + 19, r.values + r.size, points_.state(e));
        }
    }

    /// Material of local element @p e.
    const materials::Material &
    material(unsigned int e) const
    {
      return points_.material(e);
    }

    /**
     * @brief Bytes this object keeps on this rank: the per-element arrays and the history of
     * every material group (allocated capacities).
     */
    std::size_t
    memory_consumption() const
    {
      std::size_t bytes = sizeof(*this);
      const auto  add   = [&](const auto &v) { bytes += v.capacity() * sizeof(v[0]); };
      add(nodes_), add(cell_index_), add(cell_id_), add(body_), add(element_of_cell_), add(volume0_);
      add(element_dt_), add(stress_), add(q_), add(hourglass_);
      return bytes + points_.memory_consumption();
    }

  private:
    std::string hourglass_type_        = "viscous";
    bool        viscous_               = true;
    double      hourglass_coefficient_ = 0.1;
    /// Bulk viscosity Q1, Q2 (`bulk viscosity linear`, `quadratic`; default 0: off).
    materials::BulkViscosity viscosity_;

    const mesh::Discretization       *discretization_ = nullptr;
    const materials::MaterialLibrary *library_        = nullptr;
    std::vector<unsigned int>   nodes_;      // 8 per element: local index of the node's first DOF
    std::vector<unsigned int>   cell_index_; // active cell index (local)
    std::vector<std::uint64_t>  cell_id_;    // coarse cell id (the same at any rank count)
    std::vector<unsigned int>   body_;
    std::vector<int>            element_of_cell_;
    std::vector<double>         volume0_;
    std::vector<double>         element_dt_; // L_e / c_e of the last force evaluation
    std::vector<double>         stress_;     // 6 per element
    std::vector<double>         q_;          // bulk viscosity pressure of the last evaluation, per element
    std::vector<double>         hourglass_;  // 12 per element: hourglass force per mode and direction (both forms)
    /// Material groups, history and batches of the elements (one point per element).
    materials::PointStates points_;
    unsigned int              batches_per_block_ = 1;
    std::vector<unsigned int> block_order_;    // blocks of consecutive batches, colour by colour
    std::vector<unsigned int> colour_offsets_; // colour c: block_order_[colour_offsets_[c] .. [c + 1])

    /// Cuts the batches into blocks of consecutive batches, and colours
    /// the blocks so that no two blocks of one colour share a node (the blocks of a colour
    /// scatter their forces at the same time).
    void
    build_batches();

    [[noreturn]] void
    fail(unsigned int e, const mesh::Vector &d, unsigned int step, const std::string &what) const;

  public:
    /// "element <cell> of body '<name>' at (x, y, z) m" for local element @p e, the centroid in the
    /// current configuration X + @p d (ghost values of @p d needed).
    std::string
    describe(unsigned int e, const mesh::Vector &d) const;
  };
} // namespace shard::fe
