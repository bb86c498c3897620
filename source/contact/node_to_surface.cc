// SPDX-License-Identifier: LGPL-2.1-or-later
#include <shard/base/binary_archive.h>
#include <shard/contact/node_to_surface.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <map>
#include <stdexcept>
#include <string>

namespace shard::contact
{
  namespace
  {
    double
    norm(const Vec3 &a)
    {
      return std::sqrt(a[0] * a[0] + a[1] * a[1] + a[2] * a[2]);
    }
  } // namespace

  void
  NodeToSurface::reset(const ContactNodes &nodes)
  {
    const std::size_t n = nodes.size();
    candidates_.clear();
    entry_depth_.assign(n, -1.);
    penetration_.assign(n, 0.);
    segment_.assign(n, -1);
    previous_slaves_.clear();
    contact_normal_.assign(3 * n, 0.);
    planes_.clear();
    plane_stamp_.clear();
    best_.assign(n, -1);
    outside_.assign(n, 1e300);
  }

  double
  NodeToSurface::search_depth() const
  {
    return penetration_.empty() ? 0. : *std::max_element(penetration_.begin(), penetration_.end());
  }

  double
  NodeToSurface::stable_dt(const ContactNodes &nodes) const
  {
    const auto &s = settings_;
    double      dt = 1e300;
    const double damped    = damped_factor();
    double       k_segment = 0;
    for (const auto &g : nodes.segments)
      if (g.body == s.target_body || (s.symmetric && std::count(s.bodies.begin(), s.bodies.end(), g.body)))
        k_segment = std::max(k_segment, s.penalty * g.stiffness);
    // A segment node carries the reactions of the slaves around it: up to about four springs
    // of the segment stiffness at once. (Not for a rigid target: its nodes move with the mass of
    // the whole body.)
    if (!s.rigid_target)
      for (const auto &g : nodes.segments)
        if (g.body == s.target_body)
          for (const unsigned int a : g.node)
            if (nodes.nodes[a].mass > 0)
              dt = std::min(dt, damped * 2. * std::sqrt(nodes.nodes[a].mass / (4. * s.penalty * g.stiffness)));
    // Two masses on one spring: the reduced mass m/2. A node of a symmetric pair is a slave and
    // a segment node at once: twice the spring. (The stiffest segment of any rank.)
    k_segment      = global_max_(k_segment);
    const double k = k_segment * (s.symmetric ? 2. : 1.);
    for (const auto &n : nodes.nodes)
      if (std::count(s.bodies.begin(), s.bodies.end(), n.body) && n.mass > 0 && k > 0)
        dt = std::min(dt, damped * 2. * std::sqrt(0.5 * n.mass / k));
    return dt;
  }

  double
  NodeToSurface::segment_frame(const std::array<Vec3, 4> &x, Vec3 &centre, Vec3 &normal)
  {
    for (unsigned int c = 0; c < 3; ++c)
      centre[c] = 0.25 * (x[0][c] + x[1][c] + x[2][c] + x[3][c]);
    const Vec3 d1{{x[2][0] - x[0][0], x[2][1] - x[0][1], x[2][2] - x[0][2]}};
    const Vec3 d2{{x[3][0] - x[1][0], x[3][1] - x[1][1], x[3][2] - x[1][2]}};
    normal = Vec3{{d1[1] * d2[2] - d1[2] * d2[1], d1[2] * d2[0] - d1[0] * d2[2], d1[0] * d2[1] - d1[1] * d2[0]}};
    const double length = norm(normal);
    for (auto &c : normal)
      c /= length > 0 ? length : 1.;
    return length;
  }

  NodeToSurface::Plane
  NodeToSurface::mean_plane(const std::array<Vec3, 4> &x)
  {
    Plane p;
    if (!(segment_frame(x, p.centre, p.normal) > 0))
      return p;
    double extent = 0;
    for (unsigned int a = 0; a < 4; ++a)
      {
        const Vec3 &xa = x[a], &xb = x[(a + 1) % 4];
        const Vec3  r{{xa[0] - p.centre[0], xa[1] - p.centre[1], xa[2] - p.centre[2]}};
        p.half_width = std::max(p.half_width, std::abs(r[0] * p.normal[0] + r[1] * p.normal[1] + r[2] * p.normal[2]));
        extent       = std::max(extent, norm(r));
        // Triangle (xa, xb, centre), as point_segment takes it: its normal must face n.
        const Vec3 e1{{xb[0] - xa[0], xb[1] - xa[1], xb[2] - xa[2]}};
        const Vec3 e2{{p.centre[0] - xa[0], p.centre[1] - xa[1], p.centre[2] - xa[2]}};
        const Vec3 nt{{e1[1] * e2[2] - e1[2] * e2[1], e1[2] * e2[0] - e1[0] * e2[2], e1[0] * e2[1] - e1[1] * e2[0]}};
        if (!(nt[0] * p.normal[0] + nt[1] * p.normal[1] + nt[2] * p.normal[2] > 0))
          return p;
      }
    // Margin for the edge tolerance of point_segment (barycentric coordinates down to -1e-3).
    p.half_width += 0.01 * extent;
    p.usable = true;
    return p;
  }

  void
  NodeToSurface::build(const SearchContext &context)
  {
    const auto        &in       = settings_;
    const auto        &nodes    = context.nodes;
    const auto        &x        = context.x;
    const auto        &reach    = context.reach;
    const double       base     = context.base;
    const unsigned int n        = nodes.size();
    auto              &cand     = candidates_;
    cand.clear();
    // Each segment of the target (and of the bodies when symmetric) against the nodes of the
    // other side near its box: the slow nodes (reach = skin/2) from the segment's side through
    // the node grid, the fast ones from their own side through a grid of the segment centres.
    struct Box
    {
      Vec3   lo, hi, centre, normal;
      double length = 0, depth = 0, reach = 0, extent = 0;
      bool   forward = false;
    };
    std::vector<Box>          boxes;
    std::vector<unsigned int> used;
    for (unsigned int g = 0; g < nodes.segments.size(); ++g)
      {
        const auto &seg = nodes.segments[g];
        Box         b;
        b.forward           = seg.body == in.target_body;
        const bool backward = in.symmetric && nodes.member(seg.node[0], in.bodies);
        if (!b.forward && !backward)
          continue;
        b.lo = b.hi = x[seg.node[0]];
        std::array<Vec3, 4> xs;
        for (unsigned int v = 0; v < 4; ++v)
          {
            const unsigned int a = seg.node[v];
            xs[v]                = x[a];
            b.reach              = std::max(b.reach, reach[a]);
            for (unsigned int c = 0; c < 3; ++c)
              b.lo[c] = std::min(b.lo[c], x[a][c]), b.hi[c] = std::max(b.hi[c], x[a][c]);
          }
        b.length = segment_frame(xs, b.centre, b.normal);
        for (unsigned int c = 0; c < 3; ++c)
          b.extent = std::max({b.extent, b.hi[c] - b.centre[c], b.centre[c] - b.lo[c]});
        b.depth = nodes.nodes[seg.node[0]].spacing;
        boxes.push_back(b);
        used.push_back(g);
      }
    // Node i can reach segment k before the next build: inside its box grown by the depth and
    // both reaches, and within the slab -depth - reach < (x - c) . n < reach. A slave in contact
    // is followed below the face spacing by its present penetration (add_forces): its segments
    // are found that much deeper.
    const auto  &pen     = penetration_;
    const double deepest = pen.empty() ? 0. : *std::max_element(pen.begin(), pen.end());
    const auto   consider = [&](const unsigned int i, const unsigned int k) {
      const Box         &b   = boxes[k];
      const unsigned int g   = used[k];
      // A pair is evaluated on the rank that owns its slave.
      if (!nodes.nodes[i].owned)
        return;
      const double       r   = reach[i] + b.reach;
      const double       dp  = b.depth + pen[i];
      const auto        &seg = nodes.segments[g];
      if (std::count(seg.node.begin(), seg.node.end(), i))
        return;
      for (unsigned int c = 0; c < 3; ++c)
        if (x[i][c] < b.lo[c] - dp - r || x[i][c] > b.hi[c] + dp + r)
          return;
      const double distance = plane_gap(x[i], b.centre, b.normal);
      if (b.length > 0 && (distance > r || distance < -dp - r))
        return;
      const bool slave = b.forward ? nodes.member(i, in.bodies) : nodes.nodes[i].body == in.target_body;
      if (slave && (!nodes.nodes[i].particle || b.forward))
        cand.push_back({{i, g}});
    };
    // The slow nodes that can be a slave of some segment of this interaction, in their own grid:
    // a segment's box then holds no nodes of its own body that could not touch it (the
    // projectile's own surface nodes around each of its faces).
    std::vector<unsigned int> slow;
    std::vector<Vec3>         slow_x;
    for (unsigned int i = 0; i < n; ++i)
      if (reach[i] == base && nodes.nodes[i].owned &&
          (nodes.member(i, in.bodies) || (in.symmetric && nodes.nodes[i].body == in.target_body)))
        {
          slow.push_back(i);
          slow_x.push_back(x[i]);
        }
    BinGrid slow_grid;
    if (!slow.empty())
      slow_grid.build(slow_x, 2. * context.largest_radius + 2. * base);
    double widest = 0;
    for (unsigned int k = 0; k < boxes.size(); ++k)
      {
        const Box   &b = boxes[k];
        const double r = b.depth + deepest + b.reach + base;
        widest         = std::max(widest, b.extent + b.depth + deepest + b.reach);
        slow_grid.for_each_in_box(Vec3{{b.lo[0] - r, b.lo[1] - r, b.lo[2] - r}},
                                  Vec3{{b.hi[0] + r, b.hi[1] + r, b.hi[2] + r}},
                                  [&](const unsigned int t) { consider(slow[t], k); });
      }
    std::vector<Vec3> centres;
    for (const auto &b : boxes)
      centres.push_back(b.centre);
    BinGrid segment_grid;
    for (unsigned int i = 0; i < n; ++i)
      if (reach[i] > base && nodes.nodes[i].owned && !boxes.empty())
        {
          if (segment_grid.size() == 0)
            segment_grid.build(centres, 2. * widest);
          const double r = widest + reach[i];
          segment_grid.for_each_in_box(Vec3{{x[i][0] - r, x[i][1] - r, x[i][2] - r}},
                                       Vec3{{x[i][0] + r, x[i][1] + r, x[i][2] + r}},
                                       [&](const unsigned int k) { consider(i, k); });
        }
  }

  bool
  NodeToSurface::in_contact_before(const unsigned int i) const
  {
    const double *nb = &contact_normal_[3 * i];
    return nb[0] != 0 || nb[1] != 0 || nb[2] != 0;
  }

  bool
  NodeToSurface::along(const Vec3 &n, const unsigned int i) const
  {
    const double *nb = &contact_normal_[3 * i];
    return n[0] * nb[0] + n[1] * nb[1] + n[2] * nb[2] >= corner_cosine;
  }

  double
  NodeToSurface::reach_depth(const unsigned int i, const double depth) const
  {
    return in_contact_before(i) ? depth + penetration_[i] : depth;
  }

  void
  NodeToSurface::keep(const ContactNodes &nodes, const unsigned int i, const SegmentHit &h, const unsigned int g)
  {
    // (Preferring the faces of the slave's last direction instead was tried: a slave whose
    // first hit was a side face of the target, one face spacing deep, then kept it with that
    // entry offset and no force, and the head-on FE-particle bars at 10 m/s stuck together.)
    if (best_[i] < 0)
      {
        best_[i] = static_cast<int>(hits_.size());
        hits_.emplace_back(h, g);
        slaves_.push_back(i);
        return;
      }
    // Ties (a slave on the apex of faces that meet symmetrically, the nose point of the
    // projectile: the same depth under four faces to the last digit) go to the face of the
    // smallest reference position, not to the first one found: the local order of the faces
    // depends on the partition, and a different face gave the slave another normal, so runs at 1
    // and 2 ranks parted by 1e-8 within three steps (doc/manual/contact.md, "Ties").
    const double now = std::abs(h.gap), kept = std::abs(hits_[best_[i]].first.gap);
    if (now < kept - tie_tolerance * kept ||
        (now <= kept + tie_tolerance * kept && reference_before(nodes, g, hits_[best_[i]].second)))
      hits_[best_[i]] = {h, g};
  }

  bool
  NodeToSurface::reference_before(const ContactNodes &nodes, const unsigned int a, const unsigned int b)
  {
    // The four reference positions of each face, sorted: the same on every rank and partition.
    const auto sorted = [&](const unsigned int g) {
      std::array<Vec3, 4> x;
      for (unsigned int v = 0; v < 4; ++v)
        x[v] = nodes.nodes[nodes.segments[g].node[v]].X;
      std::sort(x.begin(), x.end());
      return x;
    };
    return a != b && sorted(a) < sorted(b);
  }

  bool
  NodeToSurface::turned(const unsigned int i) const
  {
    return in_contact_before(i) && !along(planes_[hits_[best_[i]].second].normal, i);
  }

  void
  NodeToSurface::note_outside(const unsigned int i, const double gap)
  {
    if (gap < outside_[i])
      {
        if (!(outside_[i] < 1e300))
          outside_nodes_.push_back(i);
        outside_[i] = gap;
      }
  }

  void
  NodeToSurface::add_forces(const ContactNodes &nodes, const unsigned int step, const double dt, ForceSink &sink)
  {
    hits_.clear();
    slaves_.clear();
    missed_.clear();
    outside_nodes_.clear();
    find_hits(nodes, step);
    retry_dead_zone(nodes);
    drop_corner_slaves(nodes);
    for (const unsigned int i : outside_nodes_)
      outside_[i] = 1e300;
    outside_nodes_.clear();
    std::sort(slaves_.begin(), slaves_.end());
    update_history(nodes, dt);
    add_springs(nodes, step, sink);
  }

  void
  NodeToSurface::find_hits(const ContactNodes &nodes, const unsigned int step)
  {
    // Per segment (once per step): the mean plane through its centre, the half width of the
    // slab that holds its four nodes, and whether its four triangles face the same way. A point
    // above that slab, or below it by more than the depth, cannot hit any of the triangles, so
    // point_segment is skipped for it.
    plane_stamp_.resize(nodes.segments.size(), ~0u);
    planes_.resize(nodes.segments.size());
    for (const auto &[i, g] : candidates_)
      {
        const auto         &seg = nodes.segments[g];
        std::array<Vec3, 4> xs;
        for (unsigned int v = 0; v < 4; ++v)
          xs[v] = nodes.position(seg.node[v]);
        const double depth = nodes.nodes[seg.node[0]].spacing;
        Plane       &pl    = planes_[g];
        if (plane_stamp_[g] != step)
          {
            plane_stamp_[g] = step;
            pl              = mean_plane(xs);
            double r2       = 0;
            for (const auto &xv : xs)
              r2 = std::max(r2, (xv[0] - pl.centre[0]) * (xv[0] - pl.centre[0]) +
                                  (xv[1] - pl.centre[1]) * (xv[1] - pl.centre[1]) +
                                  (xv[2] - pl.centre[2]) * (xv[2] - pl.centre[2]));
            pl.sphere2 = 1.0201 * r2;
          }
        const double deep = reach_depth(i, depth);
        const Vec3   p    = nodes.position(i);
        {
          const double d0 = p[0] - pl.centre[0], d1 = p[1] - pl.centre[1], d2 = p[2] - pl.centre[2];
          if (d0 * d0 + d1 * d1 + d2 * d2 > pl.sphere2 + deep * deep)
            continue;
        }
        double hgt = 0;
        if (pl.usable)
          {
            hgt = (p[0] - pl.centre[0]) * pl.normal[0] + (p[1] - pl.centre[1]) * pl.normal[1] +
                  (p[2] - pl.centre[2]) * pl.normal[2];
            if (hgt > pl.half_width || hgt < -pl.half_width - deep)
              continue;
          }
        const SegmentHit h = point_segment(p, xs, deep);
        if (!h.hit)
          {
            // Outside this face (the projection is on it): remembered for the nearest-surface
            // test.
            if (h.projected && h.gap >= 0)
              note_outside(i, h.gap);
            if (!h.projected && pl.usable && hgt < 0 && in_contact_before(i) && along(pl.normal, i))
              missed_.push_back({{i, g}});
            continue;
          }
        keep(nodes, i, h, g);
      }
  }

  void
  NodeToSurface::retry_dead_zone(const ContactNodes &nodes)
  {
    // Where the faces around a node form a valley (seen from outside; an end face that the
    // impact has dimpled), a slave pressed into it projects onto none of them within the edge
    // tolerance. It then lost its contact for a step and was caught by a side face of the target
    // one face spacing deep, with the full spring of that depth (the head-on bars at 100 m/s:
    // 68 J stored from nothing, the run stopped at 6.7 us). A slave in contact keeps the face of
    // its direction it lies under, its contact point clamped onto the face.
    // Whether a slave already has a face of its direction is decided before any retry: a retry
    // hit must not hide the other faces of the valley (the nearest of them is kept, whatever
    // their order; taking the first gave runs at 1 and 2 ranks different faces).
    std::size_t n_retry = 0;
    for (const auto &[i, g] : missed_)
      if (!(best_[i] >= 0 && along(planes_[hits_[best_[i]].second].normal, i)))
        missed_[n_retry++] = {{i, g}};
    missed_.resize(n_retry);
    for (const auto &[i, g] : missed_)
      {
        const auto         &seg = nodes.segments[g];
        std::array<Vec3, 4> xs;
        for (unsigned int v = 0; v < 4; ++v)
          xs[v] = nodes.position(seg.node[v]);
        const SegmentHit h =
          point_segment(nodes.position(i), xs, reach_depth(i, nodes.nodes[seg.node[0]].spacing), 0.05);
        if (h.hit)
          keep(nodes, i, h, g);
      }
  }

  void
  NodeToSurface::drop_corner_slaves(const ContactNodes &nodes)
  {
    // A slave whose contact turns to a face of another direction (a corner of the target) is
    // checked against the nearest surface: if it lies outside some face (its projection on the
    // face, gap >= 0) by less than it penetrates the new face, it left the body through that
    // face, and the new hit (found through the edge tolerance) is not a contact. Without this
    // test a plate node that lifted off the flat end face of a rigid projectile by a fraction of
    // a micrometre, still within the edge tolerance of a side face, counted as penetrating the
    // side face by up to the face spacing and was thrown off at km/s (doc/manual/contact.md,
    // "Corners"). A slave that stays on a face of its direction keeps it (the aligned edges of
    // two bars: the edge nodes lie on the side planes of the target and still press its end
    // face). The faces skipped by find_hits() for such a slave (above their slab by less than
    // its penetration) are projected here.
    bool any_turned = false;
    for (const unsigned int i : slaves_)
      any_turned = any_turned || turned(i);
    if (!any_turned)
      return;
    for (const auto &[i, g] : candidates_)
      {
        if (best_[i] < 0 || !turned(i))
          continue;
        const double pen = std::min(-hits_[best_[i]].first.gap, outside_[i]);
        const Plane &pl  = planes_[g];
        if (!pl.usable)
          continue; // projected above whatever its height
        const Vec3   p   = nodes.position(i);
        const double hgt = (p[0] - pl.centre[0]) * pl.normal[0] + (p[1] - pl.centre[1]) * pl.normal[1] +
                           (p[2] - pl.centre[2]) * pl.normal[2];
        // Only the faces skipped as clearly outside, and close enough to matter.
        if (!(hgt > pl.half_width) || hgt - pl.half_width >= pen)
          continue;
        const auto         &seg = nodes.segments[g];
        std::array<Vec3, 4> xs;
        for (unsigned int v = 0; v < 4; ++v)
          xs[v] = nodes.position(seg.node[v]);
        const SegmentHit h = point_segment(p, xs, nodes.nodes[seg.node[0]].spacing);
        if (h.projected && h.gap >= 0)
          note_outside(i, h.gap);
      }
    std::size_t kept = 0;
    for (const unsigned int i : slaves_)
      if (turned(i) && outside_[i] < -hits_[best_[i]].first.gap)
        best_[i] = -1;
      else
        slaves_[kept++] = i;
    slaves_.resize(kept);
  }

  void
  NodeToSurface::update_history(const ContactNodes &nodes, const double dt)
  {
    // A slave that starts a contact already deep (it slid in over the edge of a face) keeps that
    // entry depth as an offset while the contact lasts, so that no energy comes from nothing; a
    // contact that starts at the surface has none. A slave that moves on to another face keeps
    // the penetration it pressed with (its spring's energy), not the depth it finds under the
    // new face: on a faceted curved target (the ogive nose) the depth under the next facet
    // differs, and a particle went from a spring of a few micrometres to one of 1.15 mm in a
    // step, then inverted.
    auto &depth   = entry_depth_;
    auto &segment = segment_;
    for (const unsigned int i : previous_slaves_)
      if (best_[i] < 0)
        {
          depth[i]   = -1.;
          segment[i] = -1;
        }
    for (const unsigned int i : slaves_)
      {
        const double now = -hits_[best_[i]].first.gap;
        const int    g   = static_cast<int>(hits_[best_[i]].second);
        if (depth[i] >= 0 && segment[i] != g)
          {
            // The spring's energy k eff^2 / 2 goes on: the faces of one target differ in
            // stiffness (the tip face of the ogive nose is 100 times softer than its side
            // facets: a particle pressed 3.5 mm into the tip got 1.5 kJ when it moved on to a
            // side facet with the same penetration). Its penetration changes in the step by what
            // the relative normal motion allows, |v_slave - v_face| dt, not by the difference of
            // depth under the two faces (a slave in the valley between end faces found a side
            // face one face spacing deep: 68 J from nothing in the head-on bars at 100 m/s).
            const SegmentHit &h     = hits_[best_[i]].first;
            const Vec3        vi    = nodes.velocity(i);
            double            vr[3] = {vi[0], vi[1], vi[2]};
            for (unsigned int v = 0; v < 4; ++v)
              for (unsigned int c = 0; c < 3; ++c)
                vr[c] -= h.weights[v] * nodes.state[ContactNodes::state_record * nodes.segments[g].node[v] + 3 + c];
            const double motion = 1.5 * dt * std::sqrt(vr[0] * vr[0] + vr[1] * vr[1] + vr[2] * vr[2]);
            const double change = std::clamp(now - penetration_[i], -motion, motion);
            const double k_new  = nodes.segments[g].stiffness;
            const double k_old  = segment[i] >= 0 ? nodes.segments[segment[i]].stiffness : k_new;
            const double eff    = std::max(0., std::max(0., penetration_[i] - depth[i]) + change);
            depth[i]            = std::max(0., now - eff * std::sqrt(k_old / k_new));
          }
        depth[i]   = depth[i] < 0 ? now : std::min(depth[i], now);
        segment[i] = g;
      }
    for (const unsigned int i : previous_slaves_)
      if (best_[i] < 0)
        {
          std::fill_n(&contact_normal_[3 * i], 3, 0.);
          penetration_[i] = 0;
        }
    for (const unsigned int i : slaves_)
      {
        std::copy_n(planes_[hits_[best_[i]].second].normal.begin(), 3, &contact_normal_[3 * i]);
        penetration_[i] = -hits_[best_[i]].first.gap;
      }
    previous_slaves_ = slaves_;
  }

  void
  NodeToSurface::add_springs(const ContactNodes &nodes, const unsigned int step, ForceSink &sink)
  {
    const auto &in = settings_;
    for (const unsigned int i : slaves_)
      {
        const auto &[h, g] = hits_[best_[i]];
        best_[i]           = -1;
        const auto  &seg   = nodes.segments[g];
        const double fn    = in.penalty * seg.stiffness * (-h.gap - entry_depth_[i]);
        if (-h.gap - entry_depth_[i] > 0.5 * nodes.nodes[seg.node[0]].spacing && !warned_deep_)
          {
            warned_deep_ = true;
            if (print_notices_)
              std::fprintf(stderr,
                           "shard: warning: contact '%s', step %u: a penalty spring is pressed %.3g m, more than "
                           "half the face spacing %.3g m. The contact follows the slave, but the penalty is soft "
                           "for this impact (bodies may pass through); raise 'H - Contact/%s/penalty scale' "
                           "(doc/manual/contact.md, \"Time step\"). Said once.\n",
                           in.name.c_str(), step, -h.gap - entry_depth_[i], nodes.nodes[seg.node[0]].spacing,
                           in.name.c_str());
          }
        if (!(fn > 0))
          continue;
        sink.stored += 0.5 * fn * (-h.gap - entry_depth_[i]);
        Vec3 vr{{0, 0, 0}}; // slave velocity relative to the face point
        if (in.friction > 0 || in.damping > 0)
          {
            Vec3 vm{{0, 0, 0}};
            for (unsigned int v = 0; v < 4; ++v)
              for (unsigned int c = 0; c < 3; ++c)
                vm[c] += h.weights[v] * nodes.state[ContactNodes::state_record * seg.node[v] + 3 + c];
            const Vec3 vi = nodes.velocity(i);
            vr            = Vec3{{vi[0] - vm[0], vi[1] - vm[1], vi[2] - vm[2]}};
          }
        double f_normal = fn;
        if (in.damping > 0)
          {
            // The face point's mass: the weighted masses of the face nodes.
            double ms = 0;
            for (unsigned int v = 0; v < 4; ++v)
              ms += h.weights[v] * nodes.nodes[seg.node[v]].mass;
            const double mi = nodes.nodes[i].mass;
            f_normal = sink.damped_normal(fn, in.penalty * seg.stiffness, mi + ms > 0 ? mi * ms / (mi + ms) : 0.,
                                          vr[0] * h.normal[0] + vr[1] * h.normal[1] + vr[2] * h.normal[2], in.damping);
          }
        Vec3 fi{{f_normal * h.normal[0], f_normal * h.normal[1], f_normal * h.normal[2]}};
        if (in.friction > 0)
          sink.add_friction(vr, h.normal, f_normal, in.friction, fi);
        sink.add(i, fi, 1.);
        for (unsigned int v = 0; v < 4; ++v)
          sink.add(seg.node[v], fi, -h.weights[v]);
      }
  }

  void
  NodeToSurface::save(base::BinaryWriter &out) const
  {
    out.put(std::string("node to surface"));
    out.put(candidates_);
    out.put(entry_depth_);
    out.put(penetration_);
    out.put(segment_);
    out.put(previous_slaves_);
    out.put(contact_normal_);
  }

  void
  NodeToSurface::load(base::BinaryReader &in)
  {
    in.expect("node to surface");
    in.get(candidates_);
    in.get(entry_depth_);
    in.get(penetration_);
    in.get(segment_);
    in.get(previous_slaves_);
    in.get(contact_normal_);
    // The plane cache is per step and is filled again.
    plane_stamp_.clear();
    planes_.clear();
  }

  void
  NodeToSurface::write_state(base::BinaryWriter &out, const ContactNodes &nodes, const NodeNaming &naming) const
  {
    std::vector<unsigned long long> segment;
    for (unsigned int i = 0; i < nodes.size(); ++i)
      for (unsigned int v = 0; v < 4; ++v)
        segment.push_back(segment_[i] < 0 ? 0ull : naming.name(nodes.segments[segment_[i]].node[v]) + 1);
    std::vector<unsigned long long> slaves;
    for (const unsigned int i : previous_slaves_)
      slaves.push_back(naming.name(i));
    out.put(entry_depth_);
    out.put(penetration_);
    out.put(segment);
    out.put(contact_normal_);
    out.put(slaves);
  }

  void
  NodeToSurface::read_state(base::BinaryReader &in, const ContactNodes &nodes, const std::vector<int> &where,
                            const NodeNaming &naming)
  {
    std::vector<double>             entry_depth, penetration, contact_normal;
    std::vector<unsigned long long> segment, slaves;
    in.get(entry_depth);
    in.get(penetration);
    in.get(segment);
    in.get(contact_normal);
    in.get(slaves);
    if (entry_depth.size() != where.size() || 4 * where.size() != segment.size() ||
        3 * where.size() != contact_normal.size())
      throw std::runtime_error("the node-to-surface contact state does not fit its node list");
    std::map<std::array<unsigned long long, 4>, int> segment_of;
    for (unsigned int g = 0; g < nodes.segments.size(); ++g)
      segment_of.emplace(nodes.segment_dofs(g), static_cast<int>(g));
    for (std::size_t k = 0; k < where.size(); ++k)
      {
        const int i = where[k];
        if (i < 0)
          continue;
        entry_depth_[i] = entry_depth[k];
        penetration_[i] = penetration[k];
        if (segment[4 * k] > 0)
          {
            std::array<unsigned long long, 4> dofs{};
            bool                              known = true;
            for (unsigned int v = 0; v < 4; ++v)
              {
                const int j = naming.index(segment[4 * k + v] - 1);
                known       = known && j >= 0;
                dofs[v]     = j >= 0 ? nodes.nodes[j].dof + 1 : 0;
              }
            std::sort(dofs.begin(), dofs.end());
            const auto it = known ? segment_of.find(dofs) : segment_of.end();
            segment_[i]   = it == segment_of.end() ? -1 : it->second;
          }
        for (unsigned int c = 0; c < 3; ++c)
          contact_normal_[3 * i + c] = contact_normal[3 * k + c];
      }
    // The slaves of this writer (states of several writers add up).
    std::vector<int> where_of_name(nodes.size(), 0);
    for (const int i : where)
      if (i >= 0)
        where_of_name[i] = 1;
    for (const auto name : slaves)
      if (const int j = naming.index(name); j >= 0 && where_of_name[j])
        previous_slaves_.push_back(static_cast<unsigned int>(j));
    std::sort(previous_slaves_.begin(), previous_slaves_.end());
    previous_slaves_.erase(std::unique(previous_slaves_.begin(), previous_slaves_.end()), previous_slaves_.end());
    candidates_.clear();
  }

  void
  NodeToSurface::keep_notices(const Interaction &before)
  {
    if (const auto *same = dynamic_cast<const NodeToSurface *>(&before))
      warned_deep_ = same->warned_deep_;
  }
} // namespace shard::contact
