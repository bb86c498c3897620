// SPDX-License-Identifier: LGPL-2.1-or-later
/**
 * @file node_to_surface.h
 * @brief Contact type `node to surface`: nodes (FE surface nodes, particles) against the
 * boundary faces of an FE body, with the contact history that follows a slave across faces.
 * @ingroup contact
 */
#pragma once

#include <shard/contact/interaction.h>

#include <array>
#include <utility>
#include <vector>

namespace shard::contact
{
  /**
   * @brief The nodes of `body` (slaves) against the surface faces of `target` (segments);
   * `symmetric` adds the surface nodes of `target` against the faces of `body`.
   *
   * Per slave the segment it penetrates least deeply is kept (the nearest surface), with the
   * tests for the dead zone of a valley between faces and for a slave that turns a corner
   * (doc/manual/contact.md, "Corners"). The spring force is s k (penetration - entry depth)
   * with k = K A^2 / V of the face; a slave that starts a contact already deep keeps that depth
   * as an offset, and a slave that moves on to another face keeps the penetration it pressed
   * with (the contact history).
   */
  class NodeToSurface : public Interaction
  {
  public:
    using Interaction::Interaction;

    void
    reset(const ContactNodes &nodes) override;

    /// The stiffest segment spring on a slave (twice for symmetric) and on the segment nodes
    /// (up to four slaves at once; not for a rigid target).
    double
    stable_dt(const ContactNodes &nodes) const override;

    /// The deepest penetration of a slave in contact (m).
    double
    search_depth() const override;

    /// The (slave, segment) pairs that can meet before the next build, for the slaves this
    /// rank owns.
    void
    build(const SearchContext &context) override;

    void
    add_forces(const ContactNodes &nodes, unsigned int step, double dt, ForceSink &sink) override;

    void
    save(base::BinaryWriter &out) const override;

    void
    load(base::BinaryReader &in) override;

    /// Entry depths, penetrations, segments (by the names of their nodes) and contact normals
    /// per node; the slaves of the last step by name.
    void
    write_state(base::BinaryWriter &out, const ContactNodes &nodes, const NodeNaming &naming) const override;

    void
    read_state(base::BinaryReader &in, const ContactNodes &nodes, const std::vector<int> &where,
               const NodeNaming &naming) override;

    void
    keep_notices(const Interaction &before) override;

  private:
    /// The mean plane of a segment: a point with (x - centre) . normal above half_width, or
    /// below -half_width - depth, hits none of its triangles (usable: all four face normal).
    struct Plane
    {
      Vec3   centre{}, normal{};
      double half_width = 0;
      bool   usable     = false;
      /// Square of the radius around the centre (the mean of the four nodes, always set)
      /// beyond which no point hits the segment at depth 0: (1.01 R)^2, R the largest node
      /// distance; a point hits within depth d only inside sqrt(sphere2 + d^2) (a hit projects
      /// into a triangle with the centre as a corner, and the gap is normal to it).
      double sphere2 = 0;
    };
    static Plane
    mean_plane(const std::array<Vec3, 4> &x);
    /// Centre of a segment and its unit normal from the diagonals; returns the length of the
    /// diagonals' cross product (0 for a degenerate segment, whose normal is then not unit).
    static double
    segment_frame(const std::array<Vec3, 4> &x, Vec3 &centre, Vec3 &normal);

    /// The steps of add_forces(): the kept hit of every slave among its candidates (and the
    /// faces it missed in a valley), the dead-zone retry, the nearest-surface test for a slave
    /// that turned a corner, the contact history, and the springs.
    void
    find_hits(const ContactNodes &nodes, unsigned int step);
    void
    retry_dead_zone(const ContactNodes &nodes);
    void
    drop_corner_slaves(const ContactNodes &nodes);
    void
    update_history(const ContactNodes &nodes, double dt);
    void
    add_springs(const ContactNodes &nodes, unsigned int step, ForceSink &sink);

    /// Whether slave @p i was in contact at the last step (it has a contact normal).
    bool
    in_contact_before(unsigned int i) const;
    /// Whether normal @p n is of the direction slave @p i was pressed along at the last step.
    bool
    along(const Vec3 &n, unsigned int i) const;
    /// How deep a hit may lie: the face spacing @p depth, and for a slave in contact its
    /// penetration of the last step on top (it is followed however deep it is pressed).
    double
    reach_depth(unsigned int i, double depth) const;
    /// Keeps hit @p h on segment @p g for slave @p i if it is less deep than the one kept.
    void
    keep(const ContactNodes &nodes, unsigned int i, const SegmentHit &h, unsigned int g);
    /// Whether face @p a comes before face @p b by their sorted reference positions (the
    /// tie-break of keep(), the same on every partition).
    static bool
    reference_before(const ContactNodes &nodes, unsigned int a, unsigned int b);
    /// Whether kept slave @p i turned to a face of another direction.
    bool
    turned(unsigned int i) const;
    /// Remembers that node @p i lies outside a face by @p gap (the smallest per step).
    void
    note_outside(unsigned int i, double gap);

    /// Cosine of the turn of the contact normal in one step above which the nearest-surface
    /// test applies: a face of another direction (a corner of the target; the sides of a
    /// 16-sided cylinder differ by 22.5 degrees, cosine 0.92), not the same face turning.
    static constexpr double corner_cosine = 0.99;
    /// Relative difference of two depths below which keep() treats them as a tie.
    static constexpr double tie_tolerance = 1e-10;

    /// Candidates (node, segment).
    std::vector<std::array<unsigned int, 2>> candidates_;
    /// Per node: the penetration a slave in contact had when its contact began (ignored, the
    /// smallest since); -1 out of contact.
    std::vector<double> entry_depth_;
    /// Per node: the penetration -gap of a slave in contact at the last step (m), 0 out of
    /// contact. A slave in contact is followed to that depth plus the face spacing (the
    /// contact history), so a fast impact does not push it through.
    std::vector<double> penetration_;
    /// Per node: the segment a slave was in contact with at the last step, -1 out of contact or
    /// unknown (after a conversion or a restart at another rank count). A slave that moves on
    /// to another segment keeps its spring's penetration.
    std::vector<int> segment_;
    /// The slaves in contact at the last step.
    std::vector<unsigned int> previous_slaves_;
    /// 3 per node: the unit normal of the face a slave was in contact with at the last step,
    /// (0, 0, 0) out of contact. A slave whose contact turns (cosine below corner_cosine) is
    /// checked against the nearest surface.
    std::vector<double> contact_normal_;
    /// Whether the warning of a spring pressed more than half the face spacing was given.
    bool warned_deep_ = false;

    // Work space of one evaluation.
    /// Per segment (once per step): its mean plane, and the step it was computed at.
    std::vector<Plane>        planes_;
    std::vector<unsigned int> plane_stamp_;
    /// Per slave the kept hit and its segment; the slaves with a hit.
    std::vector<std::pair<SegmentHit, unsigned int>> hits_;
    std::vector<unsigned int>                        slaves_;
    /// Per node the index of its kept hit in hits_, -1 for none.
    std::vector<int> best_;
    /// Per node the smallest gap >= 0 of a face it lies outside of (its projection on the face)
    /// in this step (m); 1e300 for none. A slave outside a face by less than it penetrates its
    /// kept face is not in contact (the nearest surface decides). outside_nodes_ lists the
    /// nodes set in this step.
    std::vector<double>       outside_;
    std::vector<unsigned int> outside_nodes_;
    /// Faces of its direction under which a slave in contact lies but onto which it does not
    /// project (the dead zone of a valley between faces).
    std::vector<std::array<unsigned int, 2>> missed_;
  };
} // namespace shard::contact
