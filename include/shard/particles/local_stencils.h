// SPDX-License-Identifier: LGPL-2.1-or-later
/**
 * @file local_stencils.h
 * @brief The stencil builder: the RK and smoothing stencils of a rank's owned particles on
 *        compact local arrays (owned, then the one- and two-hop ghost particles).
 * @ingroup particles
 */
#pragma once

#include <shard/particles/rk_shape.h>
#include <shard/particles/spg_kernel.h>

#include <vector>

namespace shard::particles
{
  /// Particle data a stencil build needs, indexed by cloud position (sorted by global id).
  struct ParticleCloud
  {
    /// Reference positions.
    std::vector<Point3> position;
    /// Spacing per direction (support radius = dilation x spacing).
    std::vector<Point3> spacing;
    /// 1 where the interpolation row is replaced by the identity (u_J = d_J): particles with
    /// an essential or traction boundary condition.
    std::vector<unsigned char> interpolating;
    /// Connected component per particle; supports do not reach across components. Empty: one.
    std::vector<unsigned int> component;
  };

  /**
   * @brief The stencils of one rank: A over the rows J, G over the owned rows I, and the map
   * from compact coefficient index K to cloud index.
   */
  struct LocalStencils
  {
    /// A: n_j rows (particles J), columns compact K; psi only (grad left empty), identity rows
    /// where interpolating.
    Stencil a;
    /// G: n_i rows (owned particles I), columns compact J; grad used (grad Psi~_J(X_I)).
    Stencil g;
    /// Cloud index of each compact coefficient K (owned first, in the order given).
    std::vector<unsigned int> cloud_index;
    unsigned int              n_i = 0, n_j = 0, n_k = 0;
    /// Owned rows whose moment matrix fell back to Shepard functions (cloud indices).
    std::vector<unsigned int> fallback;

    /**
     * @brief Bytes held by the stencils: the CSR arrays of A and G (offsets, columns, psi,
     * grad, fallback flags, rcond; allocated capacities), the compact index and the fallback
     * list, plus the struct itself.
     */
    std::size_t
    memory_consumption() const;
  };

  /**
   * @brief Builds the local stencils for the owned particles @p owned (cloud indices, in the
   * order in which they become rows I) from the whole cloud.
   *
   * J = owned, then the other particles in the supports of the owned ones; K = J, then the
   * particles in the supports of every J (the two-hop set). Deterministic: neighbours are
   * summed in cloud order, so the stencils do not depend on the partition.
   */
  LocalStencils
  build_local_stencils(const ParticleCloud &cloud, const std::vector<unsigned int> &owned,
                       const RkParameters &params);

} // namespace shard::particles
