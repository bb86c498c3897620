// SPDX-License-Identifier: LGPL-2.1-or-later
/**
 * @file point_states.h
 * @brief The material points of a force class (FE elements or particles): material groups,
 *        history slots, batches of one material call, stress work and bulk viscosity.
 * @ingroup materials
 */
#pragma once

#include <shard/materials/material.h>

#include <cmath>
#include <cstddef>
#include <string>
#include <vector>

namespace shard::materials
{
  /// Points per material call.
  constexpr unsigned int point_batch_size = 64;

  /**
   * @brief The material points of one force class, numbered 0..n-1 by their owner (HexForce:
   * local elements; SpgForce: owned particles) and grouped by material into contiguous ranges.
   *
   * Each group holds the history of its points (Material::state_slot_names() order, one row per
   * point) and is cut into batches of at most point_batch_size points: one virtual material
   * call per batch (update()). Rigid materials get no batch (no stress, no step limit). The
   * owner keeps kinematics and assembly; this class keeps what both force classes share.
   */
  class PointStates
  {
  public:
    /// The points [begin, end) of one material and their history (n_slots per point).
    struct Group
    {
      const Material          *material = nullptr;
      unsigned int             begin = 0, end = 0, n_slots = 0;
      std::vector<std::string> slot_names;
      std::vector<double>      state;
    };

    /// Points [begin, end) of group @p group.
    struct Batch
    {
      unsigned int group, begin, end;
    };

    /**
     * @brief Sets the groups: point i belongs to group @p group_of[i] (non-decreasing), group g
     * has material @p materials[g] (a group may be empty). The history is initialized
     * (Material::initialize_state) and the fields of the position set from @p positions (3 per
     * point: reference position or centroid; Material::set_position_fields).
     */
    void
    build(const std::vector<const Material *> &materials, const std::vector<unsigned int> &group_of,
          const double *positions);

    /// Removes the points with @p drop[i] (history kept, order kept); groups shrink.
    void
    remove(const std::vector<bool> &drop);

    /// Number of points.
    unsigned int
    size() const
    {
      return static_cast<unsigned int>(group_of_.size());
    }

    /// The material groups, in point order.
    const std::vector<Group> &
    groups() const
    {
      return groups_;
    }

    /// The batches, in point order (rebuilt by build() and remove()).
    const std::vector<Batch> &
    batches() const
    {
      return batches_;
    }

    /// Material of point @p i.
    const Material &
    material(const unsigned int i) const
    {
      return *groups_[group_of_[i]].material;
    }

    /// Number of history slots of point @p i.
    unsigned int
    n_slots(const unsigned int i) const
    {
      return groups_[group_of_[i]].n_slots;
    }

    /// History slots of point @p i.
    const double *
    state(const unsigned int i) const
    {
      const auto &g = groups_[group_of_[i]];
      return g.state.data() + std::size_t(i - g.begin) * g.n_slots;
    }

    /// History slots of point @p i, writable.
    double *
    state(const unsigned int i)
    {
      auto &g = groups_[group_of_[i]];
      return g.state.data() + std::size_t(i - g.begin) * g.n_slots;
    }

    /// A named history slot of point @p i (0 if its material has no such slot).
    double
    state_value(unsigned int i, const std::string &name) const;

    /**
     * @brief One material call for batch @p b: Cauchy stress and history of its points from the
     * strain increments @p de (6 per point), relative volumes @p J and lengths @p length (one per
     * point); the wave speeds go to @p c. @p stress is the owner's stress array of all points
     * (6 per point).
     */
    void
    update(const Batch &b, double dt, const double *de, const double *J, const double *length, double *stress,
           double *c);

    /// Bytes kept: the history of every group and the index arrays (capacities).
    std::size_t
    memory_consumption() const;

  private:
    std::vector<Group>        groups_;
    std::vector<unsigned int> group_of_;
    std::vector<Batch>        batches_;

    void
    build_batches();
  };

  /// The order in which stress_work() sums the six components (each force class keeps its own).
  enum class WorkOrder
  {
    /// sum of the normal terms, then the shear terms (HexForce).
    normal_then_shear,
    /// per direction a, the normal term a plus the shear term a + 3 (SpgForce).
    pairs
  };

  /**
   * @brief Stress work of a point over a step by the trapezoid rule, V_mid (sigma_old +
   * sigma_new) : de / 2 (Voigt order xx yy zz yz xz xy, shear strains as tensor components).
   */
  inline double
  stress_work(const double *stress_old, const double *stress_new, const double *de, const double volume_mid,
              const WorkOrder order)
  {
    double work = 0;
    if (order == WorkOrder::normal_then_shear)
      {
        for (unsigned int i = 0; i < 3; ++i)
          work += (stress_old[i] + stress_new[i]) * de[i];
        for (unsigned int i = 3; i < 6; ++i)
          work += 2. * (stress_old[i] + stress_new[i]) * de[i];
      }
    else
      for (unsigned int a = 0; a < 3; ++a)
        work += (stress_old[a] + stress_new[a]) * de[a] + 2. * (stress_old[a + 3] + stress_new[a + 3]) * de[a + 3];
    work *= 0.5 * volume_mid;
    return work;
  }

  /**
   * @brief Bulk viscosity in compression, q = rho L (Q2 L tr(D)^2 - Q1 c tr(D)) for tr(D) < 0
   * (von Neumann-Richtmyer with a linear term; LS-DYNA's form), and its limit of the step.
   */
  struct BulkViscosity
  {
    /// Linear and quadratic coefficients Q1, Q2.
    double q1 = 0, q2 = 0;

    /**
     * @brief The viscous pressure q of a point for the step with volumetric strain increment
     * @p trd (not stored in the stress); its work, with the mean of the q of both ends of the
     * step (@p q_old, then set to q), is subtracted from @p work.
     */
    double
    apply(const double rho, const double length, const double c, const double trd, const double dt,
          const double volume_mid, double &q_old, double &work) const
    {
      const double q = pressure(rho, length, c, trd, dt);
      work -= 0.5 * (q_old + q) * trd * volume_mid;
      q_old = q;
      return q;
    }

    /// The viscous pressure q alone (0 in expansion or for dt = 0).
    double
    pressure(const double rho, const double length, const double c, const double trd, const double dt) const
    {
      if (!(trd < 0 && dt > 0))
        return 0.;
      const double rate = trd / dt;
      return rho * length * (q2 * length * rate * rate - q1 * c * rate);
    }

    /**
     * @brief The stable step L / (c (sqrt(1 + r^2) + r)) of a point, r = Q1 - Q2 L tr(de) / (dt c)
     * in compression and Q1 otherwise (LS-DYNA's correction of L / c).
     */
    double
    stable_step(const double length, const double c, const double trd, const double dt) const
    {
      const double r = q1 - (trd < 0 && dt > 0 ? q2 * length * trd / dt / c : 0.);
      return length / (c * (std::sqrt(1 + r * r) + r));
    }

    /// The factor by which the linear term lowers every step from the first one on, sqrt(1 + Q1^2) + Q1.
    double
    initial_step_factor() const
    {
      return std::sqrt(1 + q1 * q1) + q1;
    }
  };
} // namespace shard::materials
