// SPDX-License-Identifier: LGPL-2.1-or-later
/**
 * @file contact_nodes.h
 * @brief The contact nodes and segments every contact interaction works on (a rank's own and
 * its halo, Contact), their positions and velocities of the step, and how a contact state names its nodes
 * when it moves to another node list.
 * @ingroup contact
 *
 * Pure C++17 (no deal.II headers), so that an interaction can be tested on a hand-made node set.
 */
#pragma once

#include <shard/contact/contact_geometry.h>

#include <algorithm>
#include <array>
#include <functional>
#include <vector>

/// The checkpoint archives (base/binary_archive.h) every contact class reads and writes.
namespace shard::base
{
  class BinaryWriter;
  class BinaryReader;
} // namespace shard::base

namespace shard::contact
{
  /// A contact node: an FE surface node or a particle, one per contact DOF triple of any rank.
  struct ContactNode
  {
    /// Global DOF of the x component.
    unsigned long long dof = 0;
    /// Reference position (m).
    Vec3 X{};
    /// Support radii of a particle's RK functions (a bond reaches that far; m), 0 for FE nodes.
    Vec3 support{};
    /// Lumped mass (kg), contact sphere radius (m, 0 for FE nodes), bulk modulus of its body
    /// (Pa) and spacing (m: the particle spacing or the cube root of the element volume).
    double mass = 0, radius = 0, bulk = 0, spacing = 0;
    /// Body index ('B - Mesh/body names').
    unsigned int body = 0;
    /// Whether it is a particle.
    bool particle = false;
    /// Whether this rank owns it (Contact's halo holds nodes of other ranks): a pair is
    /// evaluated on one rank only, the owner of its slave, of its particle of smaller DOF or of
    /// its node against a wall.
    bool owned = true;
  };

  /// A boundary face of an intact hexahedron: four contact node indices, counter-clockwise seen
  /// from outside, and its penalty stiffness K A^2 / V before the penalty scale (N/m).
  struct ContactSegment
  {
    std::array<unsigned int, 4> node{};
    double                      stiffness = 0;
    unsigned int                body      = 0;
  };

  /**
   * @brief The contact nodes and segments of a rank (its own and its halo) and the state of the
   * step: positions X + d and velocities, set at the exchange (Contact::exchange()).
   */
  struct ContactNodes
  {
    /// Doubles per node in state: x (3) and v (3).
    static constexpr unsigned int state_record = 6;

    std::vector<ContactNode>    nodes;
    std::vector<ContactSegment> segments;
    /// x (3) and v (3) per node, in node order (m, m/s).
    std::vector<double> state;

    /// Number of nodes.
    unsigned int
    size() const
    {
      return static_cast<unsigned int>(nodes.size());
    }

    /// Current position of node @p i (m).
    Vec3
    position(const unsigned int i) const
    {
      return Vec3{{state[state_record * i], state[state_record * i + 1], state[state_record * i + 2]}};
    }

    /// Current velocity of node @p i (m/s).
    Vec3
    velocity(const unsigned int i) const
    {
      return Vec3{{state[state_record * i + 3], state[state_record * i + 4], state[state_record * i + 5]}};
    }

    /// Whether node @p i belongs to one of @p bodies.
    bool
    member(const unsigned int i, const std::vector<unsigned int> &bodies) const
    {
      return std::count(bodies.begin(), bodies.end(), nodes[i].body) > 0;
    }

    /// The DOFs + 1 of the four nodes of segment @p g, sorted: a name of the segment that does
    /// not depend on the segment order (which changes at a conversion). 0 stands for none.
    std::array<unsigned long long, 4>
    segment_dofs(const unsigned int g) const
    {
      std::array<unsigned long long, 4> dofs;
      for (unsigned int v = 0; v < 4; ++v)
        dofs[v] = nodes[segments[g].node[v]].dof + 1;
      std::sort(dofs.begin(), dofs.end());
      return dofs;
    }
  };

  /**
   * @brief How a contact state names its nodes when it is written for another node list: a
   * conversion (names are global DOFs) or a restart at another rank count (names are the
   * checkpoint's node keys).
   */
  struct NodeNaming
  {
    /// The name of node index i of the list that writes.
    std::function<unsigned long long(unsigned int)> name;
    /// The node index of a name in the list that reads; -1 when it is not a contact node there
    /// (its state is dropped). May throw for a name that must exist.
    std::function<int(unsigned long long)> index;
  };
} // namespace shard::contact
