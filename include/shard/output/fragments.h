// SPDX-License-Identifier: LGPL-2.1-or-later
/**
 * @file fragments.h
 * @brief Fragments: connected components of the nodes through intact elements and particle
 *        bonds, with mass, centre of mass, velocity and kinetic energy (issue 6, first part).
 * @ingroup output
 */
#pragma once

#include <shard/fe/hex_force.h>
#include <shard/mesh/discretization.h>
#include <shard/particles/particle_set.h>

#include <array>
#include <string>
#include <vector>

namespace shard::output
{
  /// One fragment: a connected set of nodes and particles.
  struct Fragment
  {
    /// Smallest coarse-mesh vertex index of the fragment's nodes: the same at any number of ranks.
    unsigned long long id = 0;
    /// Nodes (FE nodes and particles) and, of them, particles.
    unsigned long long nodes = 0, particles = 0;
    /// Mass (kg), centre of mass (m), velocity = momentum / mass (m/s), kinetic energy (J).
    double                mass = 0;
    std::array<double, 3> centre{}, velocity{};
    double                kinetic_energy = 0;
  };

  /**
   * @brief Finds the fragments: two nodes are connected when an intact element holds both or
   * when one particle lies in the RK stencil of the other (a bond). Bodies never share nodes,
   * so without failure every connected body is one fragment. prepare() joins the owned and
   * ghost nodes of this rank into local components (union-find over the edges); compute()
   * gives every local component the smallest coarse-mesh vertex index among its nodes and lets the
   * owners combine ghost labels by min, until no label changes on any rank. So 1 and 2 ranks
   * give the same fragments, and a sweep costs one pass over the nodes.
   */
  class Fragments
  {
  public:
    /// Collects the edges of the owned elements and particle rows. Call again after a rebuild.
    void
    prepare(const mesh::Discretization &discretization, const fe::HexForce &hex,
            const particles::ParticleSet &particles);

    /**
     * @brief The fragments, sorted by id, on every rank.
     * @param d physical displacement (ghost values not needed)
     * @param v velocity
     * @param mass lumped mass
     * @note Collective.
     */
    std::vector<Fragment>
    compute(const mesh::Vector &d, const mesh::Vector &v, const mesh::Vector &mass) const;

  private:
    const mesh::Discretization *discretization_ = nullptr;
    /// Local components: first local DOF of every owned or ghost node, grouped by component
    /// (members of component c at [offsets_[c], offsets_[c + 1])).
    std::vector<unsigned int> members_, offsets_;
    /// Coarse-mesh vertex index of every owned node (by first local DOF / 3).
    std::vector<unsigned int> node_id_;
    /// 1 for owned nodes that are particles (by first local DOF / 3).
    std::vector<unsigned char> particle_;
  };
} // namespace shard::output
