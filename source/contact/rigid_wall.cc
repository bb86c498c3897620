// SPDX-License-Identifier: LGPL-2.1-or-later
#include <shard/base/binary_archive.h>
#include <shard/contact/rigid_wall.h>

#include <algorithm>
#include <cmath>
#include <string>

namespace shard::contact
{
  void
  RigidWall::reset(const ContactNodes &)
  {
    candidates_.clear();
  }

  double
  RigidWall::stable_dt(const ContactNodes &nodes) const
  {
    // The wall does not move: the node's own mass.
    return node_spring_dt(nodes, 1.);
  }

  void
  RigidWall::build(const SearchContext &context)
  {
    candidates_.clear();
    for (unsigned int i = 0; i < context.nodes.size(); ++i)
      if (context.nodes.nodes[i].owned && context.nodes.member(i, settings_.bodies) &&
          plane_gap(context.x[i], settings_.point, settings_.normal) < 2. * context.reach[i])
        candidates_.push_back(i);
  }

  void
  RigidWall::add_forces(const ContactNodes &nodes, unsigned int, double, ForceSink &sink)
  {
    const auto &in = settings_;
    for (const unsigned int i : candidates_)
      {
        const double gap = plane_gap(nodes.position(i), in.point, in.normal);
        if (gap >= 0)
          continue;
        const double k      = in.penalty * nodes.nodes[i].bulk * nodes.nodes[i].spacing;
        const double spring = k * (-gap);
        sink.stored += 0.5 * spring * (-gap);
        const Vec3   vi = nodes.velocity(i);
        const double fn = sink.damped_normal(spring, k, nodes.nodes[i].mass,
                                             vi[0] * in.normal[0] + vi[1] * in.normal[1] + vi[2] * in.normal[2],
                                             in.damping);
        Vec3         fvec{{fn * in.normal[0], fn * in.normal[1], fn * in.normal[2]}};
        if (in.friction > 0)
          sink.add_friction(vi, in.normal, fn, in.friction, fvec);
        sink.add(i, fvec, 1.);
        sink.wall_force += fn;
      }
  }

  void
  RigidWall::save(base::BinaryWriter &out) const
  {
    out.put(std::string("rigid wall"));
    out.put(candidates_);
  }

  void
  RigidWall::load(base::BinaryReader &in)
  {
    in.expect("rigid wall");
    in.get(candidates_);
  }

  void
  RigidWall::write_state(base::BinaryWriter &, const ContactNodes &, const NodeNaming &) const
  {}

  void
  RigidWall::read_state(base::BinaryReader &, const ContactNodes &, const std::vector<int> &, const NodeNaming &)
  {
    candidates_.clear();
  }
} // namespace shard::contact
