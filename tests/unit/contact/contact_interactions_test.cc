// SPDX-License-Identifier: LGPL-2.1-or-later
// Unit tests of the contact interactions (particle pairs, rigid wall, node to surface) and the
// bond filter on hand-made node sets, against closed forms: the head-on collision of two
// particles (contact time, largest overlap, restitution with and without the dashpot), the
// energy that returns on separation, the ignored initial overlap, the wall spring and the
// reactions of a face.
#include <shard/contact/bond_filter.h>
#include <shard/contact/contact_nodes.h>
#include <shard/contact/node_to_surface.h>
#include <shard/contact/particle_pairs.h>
#include <shard/contact/rigid_wall.h>

#include <gtest/gtest.h>

#include <array>
#include <cmath>
#include <vector>

namespace
{
  using namespace shard::contact;

  constexpr double pi = 3.14159265358979323846;

  /// Material and size of the test particles: steel-like bulk modulus, 2 mm spacing.
  constexpr double bulk = 160e9, spacing = 2e-3, mass = 7850 * spacing * spacing * spacing, penalty = 0.1;

  ContactNode
  particle(const double x, const unsigned int id, const unsigned int body = 0)
  {
    ContactNode n;
    n.dof      = 3ull * id;
    n.X        = Vec3{{x, 0, 0}};
    n.support  = Vec3{{1.5 * spacing, 1.5 * spacing, 1.5 * spacing}};
    n.mass     = mass;
    n.radius   = 0.5 * spacing;
    n.bulk     = bulk;
    n.spacing  = spacing;
    n.body     = body;
    n.particle = true;
    return n;
  }

  /// Sets the state (x, v) of the node set from positions and velocities along x.
  void
  set_state(ContactNodes &nodes, const std::vector<double> &x, const std::vector<double> &v)
  {
    nodes.state.assign(ContactNodes::state_record * nodes.size(), 0.);
    for (unsigned int i = 0; i < nodes.size(); ++i)
      {
        nodes.state[ContactNodes::state_record * i]     = x[i];
        nodes.state[ContactNodes::state_record * i + 3] = v[i];
      }
  }

  /// Builds the candidates of @p interaction with a reach that covers the whole test.
  void
  build_all(Interaction &interaction, const ContactNodes &nodes, const BondFilter &bonds, const double reach)
  {
    std::vector<Vec3> x(nodes.size());
    for (unsigned int i = 0; i < nodes.size(); ++i)
      x[i] = nodes.position(i);
    const std::vector<double> reaches(nodes.size(), reach);
    const SearchContext       context{nodes, x, reaches, reach, 0.5 * spacing, bonds};
    interaction.build(context);
  }

  InteractionSettings
  particle_settings(const double damping)
  {
    InteractionSettings s;
    s.name      = "debris";
    s.type_text = "particles";
    s.bodies    = {0};
    s.penalty   = penalty;
    s.damping   = damping;
    return s;
  }

  /// What a head-on collision of two free particles gave.
  struct Collision
  {
    double contact_time = 0, largest_overlap = 0, largest_stored = 0, restitution = 0, damping_energy = 0;
    double momentum_before = 0, momentum_after = 0;
  };

  /// Two particles approaching each other at relative speed @p v0, integrated with central
  /// differences (kick, drift) at step @p dt until they are apart again.
  Collision
  collide(const double damping, const double v0, const double dt)
  {
    ContactNodes nodes;
    nodes.nodes = {particle(0, 0), particle(1.01 * spacing, 1)};
    std::vector<double> x = {0, 1.01 * spacing}, v = {0.5 * v0, -0.5 * v0};
    set_state(nodes, x, v);
    BondFilter bonds;
    bonds.reset(nodes);
    // Free particles: no bond between them.
    bonds.sync({}, {0, 1});
    ParticlePairs pairs(particle_settings(damping));
    pairs.reset(nodes);
    build_all(pairs, nodes, bonds, spacing);
    EXPECT_EQ(pairs.candidates().size(), 1u);

    Collision c;
    c.momentum_before = mass * (v[0] + v[1]);
    bool   touched = false;
    double t       = 0, t_first = 0, t_last = 0;
    for (unsigned int step = 0; step < 200000; ++step)
      {
        set_state(nodes, x, v);
        std::vector<double> force(6, 0.);
        ForceSink           sink(force, 1e-3);
        pairs.add_forces(nodes, step, dt, sink);
        c.damping_energy += sink.damping_power * dt;
        c.largest_stored = std::max(c.largest_stored, sink.stored);
        c.largest_overlap = std::max(c.largest_overlap, spacing - (x[1] - x[0]));
        if (force[0] != 0)
          {
            if (!touched)
              t_first = t;
            touched = true;
            t_last  = t;
          }
        else if (touched && x[1] - x[0] > spacing)
          break;
        for (unsigned int i = 0; i < 2; ++i)
          {
            v[i] += dt * force[3 * i] / mass;
            x[i] += dt * v[i];
          }
        t += dt;
      }
    c.contact_time   = t_last - t_first + dt;
    c.restitution    = (v[1] - v[0]) / v0;
    c.momentum_after = mass * (v[0] + v[1]);
    return c;
  }

  /// Nodes 0-3: a face of body 1 (the target) in the plane z = 0, edge @p L, counter-clockwise
  /// seen from +z, stiffness K A^2 / V of a cube of edge L; node 4: a slave of body 0 at the
  /// face's centre. Unit masses.
  ContactNodes
  face_and_slave(const double L)
  {
    ContactNodes nodes;
    const double xy[5][2] = {{0, 0}, {L, 0}, {L, L}, {0, L}, {0.5 * L, 0.5 * L}};
    for (unsigned int a = 0; a < 5; ++a)
      {
        ContactNode n;
        n.dof     = 3 * a;
        n.X       = Vec3{{xy[a][0], xy[a][1], 0}};
        n.mass    = 1;
        n.bulk    = bulk;
        n.spacing = L;
        n.body    = a < 4 ? 1 : 0;
        nodes.nodes.push_back(n);
      }
    ContactSegment face;
    face.node      = {{0, 1, 2, 3}};
    face.stiffness = bulk * L;
    face.body      = 1;
    nodes.segments = {face};
    return nodes;
  }

  /// Node to surface: the nodes of body 0 (slaves) against the faces of body 1.
  InteractionSettings
  surface_settings()
  {
    InteractionSettings settings;
    settings.name        = "impact";
    settings.type_text   = "node to surface";
    settings.bodies      = {0};
    settings.target_body = 1;
    settings.penalty     = penalty;
    return settings;
  }

  /// Every node at its reference position, except node @p slave, whose z is @p z.
  void
  place(ContactNodes &nodes, const unsigned int slave, const double z)
  {
    nodes.state.assign(ContactNodes::state_record * nodes.size(), 0.);
    for (unsigned int i = 0; i < nodes.size(); ++i)
      for (unsigned int c = 0; c < 3; ++c)
        nodes.state[ContactNodes::state_record * i + c] = nodes.nodes[i].X[c];
    nodes.state[ContactNodes::state_record * slave + 2] = z;
  }
} // namespace

// Elastic collision (no dashpot): a linear spring k = s K h between two masses m, reduced mass
// m/2. Contact time pi sqrt(m*/k), largest overlap v0 sqrt(m*/k), the energy stored at the
// largest overlap is the kinetic energy of the relative motion, and all of it returns: the pair
// separates at the speed it approached with.
TEST(ParticlePairs, ElasticHeadOnCollisionMatchesTheSpringClosedForm)
{
  const double k = penalty * bulk * spacing, m_star = 0.5 * mass, omega = std::sqrt(k / m_star);
  const double v0 = 10.;
  const double dt = (pi / omega) / 2000.;
  const auto   c  = collide(0., v0, dt);
  EXPECT_NEAR(c.contact_time, pi / omega, 2e-3 * pi / omega);
  EXPECT_NEAR(c.largest_overlap, v0 / omega, 2e-3 * v0 / omega);
  EXPECT_NEAR(c.largest_stored, 0.5 * m_star * v0 * v0, 2e-3 * 0.5 * m_star * v0 * v0);
  EXPECT_NEAR(c.restitution, 1., 1e-3);
  EXPECT_EQ(c.damping_energy, 0.);
  EXPECT_NEAR(c.momentum_after, c.momentum_before, 1e-12 * mass * v0);
}

// With the dashpot of ratio zeta the normal force is max(0, k delta + c delta'), c = 2 zeta
// sqrt(k m*). Until the force first vanishes the overlap is the damped oscillation
// delta = v0/omega_d exp(-zeta omega t) sin(omega_d t); after that the force stays 0 (it would
// pull), so the pair leaves with the relative speed -delta'(t*) at the root t* of
// k delta + c delta' = 0. The energy the pair loses is what the dashpot booked.
TEST(ParticlePairs, DampedCollisionRestitutionAndDissipationMatchClosedForm)
{
  const double zeta = 0.2, v0 = 10.;
  const double k = penalty * bulk * spacing, m_star = 0.5 * mass, omega = std::sqrt(k / m_star);
  const double omega_d = omega * std::sqrt(1 - zeta * zeta), c_damp = 2 * zeta * std::sqrt(k * m_star);
  const auto   delta   = [&](const double t) { return v0 / omega_d * std::exp(-zeta * omega * t) * std::sin(omega_d * t); };
  const auto   rate    = [&](const double t) {
    return v0 * std::exp(-zeta * omega * t) * (std::cos(omega_d * t) - zeta * omega / omega_d * std::sin(omega_d * t));
  };
  // Root of the force in (pi / (2 omega_d), pi / omega_d), by bisection.
  double lo = 0.5 * pi / omega_d, hi = pi / omega_d;
  for (int it = 0; it < 200; ++it)
    {
      const double mid = 0.5 * (lo + hi);
      (k * delta(mid) + c_damp * rate(mid) > 0 ? lo : hi) = mid;
    }
  const double e_closed = -rate(lo) / v0;
  // Without the clipping it would be exp(-zeta pi / sqrt(1 - zeta^2)) = 0.527 (contact.md).
  ASSERT_GT(e_closed, std::exp(-zeta * pi / std::sqrt(1 - zeta * zeta)));

  const auto c = collide(zeta, v0, (pi / omega) / 4000.);
  EXPECT_NEAR(c.restitution, e_closed, 3e-3);
  EXPECT_NEAR(c.contact_time, lo, 3e-3 * lo);
  const double lost = 0.5 * m_star * v0 * v0 * (1 - c.restitution * c.restitution);
  EXPECT_NEAR(c.damping_energy, lost, 1e-3 * 0.5 * m_star * v0 * v0);
  EXPECT_NEAR(c.momentum_after, c.momentum_before, 1e-12 * mass * v0);
}

// An overlap a pair already has when it first meets (neighbours whose bond just broke in a
// compressed zone) pushes nothing; only what it closes beyond that does.
TEST(ParticlePairs, InitialOverlapIsIgnoredAndOnlyFurtherOverlapPushes)
{
  ContactNodes nodes;
  nodes.nodes = {particle(0, 0), particle(0.9 * spacing, 1)};
  set_state(nodes, {0, 0.9 * spacing}, {0, 0});
  BondFilter bonds;
  bonds.reset(nodes);
  bonds.sync({}, {0, 1});
  ParticlePairs pairs(particle_settings(0.));
  pairs.reset(nodes);
  build_all(pairs, nodes, bonds, spacing);
  std::vector<double> force(6, 0.);
  {
    ForceSink sink(force, 1e-3);
    pairs.add_forces(nodes, 0, 1e-9, sink);
    EXPECT_EQ(force[0], 0.);
    EXPECT_EQ(sink.stored, 0.);
  }
  // Closer by 0.05 h: the spring acts on that alone.
  set_state(nodes, {0, 0.85 * spacing}, {0, 0});
  std::fill(force.begin(), force.end(), 0.);
  ForceSink sink(force, 1e-3);
  pairs.add_forces(nodes, 1, 1e-9, sink);
  const double k = penalty * bulk * spacing;
  EXPECT_NEAR(force[3], k * 0.05 * spacing, 1e-9 * k * spacing);
  EXPECT_NEAR(force[0], -k * 0.05 * spacing, 1e-9 * k * spacing);
  EXPECT_NEAR(sink.stored, 0.5 * k * 0.05 * spacing * 0.05 * spacing, 1e-9 * k * spacing * spacing);
}

// Bonded neighbours are no contact candidates; the pair wakes when its bond breaks.
TEST(ParticlePairs, BondedPairSleepsUntilItsBondBreaks)
{
  ContactNodes nodes;
  nodes.nodes = {particle(0, 0), particle(spacing, 1), particle(2 * spacing, 2)};
  set_state(nodes, {0, spacing, 2 * spacing}, {0, 0, 0});
  BondFilter bonds;
  bonds.reset(nodes);
  EXPECT_TRUE(bonds.bonded(nodes, 0, 1));
  EXPECT_TRUE(bonds.bonded(nodes, 1, 2));
  // 0 and 2 are 2 h apart, outside each other's support (1.5 h): no bond.
  EXPECT_FALSE(bonds.bonded(nodes, 0, 2));
  ParticlePairs pairs(particle_settings(0.));
  pairs.reset(nodes);
  build_all(pairs, nodes, bonds, 0.6 * spacing);
  // Within reach (2 r + 2 reach = 2.2 h): (0, 1) and (1, 2) bonded, (0, 2) not.
  ASSERT_EQ(pairs.candidates().size(), 1u);
  EXPECT_EQ(pairs.candidates()[0], (std::array<unsigned int, 2>{{0, 2}}));
  // The bond of particles 1 and 2 (ids 1, 2) breaks.
  const BondNews news = bonds.sync({{1ull, 2ull}}, {});
  ASSERT_EQ(news.broken.size(), 1u);
  EXPECT_FALSE(bonds.bonded(nodes, 1, 2));
  EXPECT_TRUE(bonds.bonded(nodes, 0, 1));
  pairs.wake(news);
  ASSERT_EQ(pairs.candidates().size(), 2u);
  EXPECT_EQ(pairs.candidates()[1], (std::array<unsigned int, 2>{{1, 2}}));
  // Particle 0 becomes free: its pair with 1 wakes too.
  const BondNews freed = bonds.sync({{1ull, 2ull}}, {0ull});
  ASSERT_EQ(freed.freed.size(), 1u);
  pairs.wake(freed);
  EXPECT_EQ(pairs.candidates().size(), 3u);
}

// A node below a rigid wall by g: the spring k g along the wall normal, k = s K h, its energy
// k g^2 / 2, and the wall takes the reaction.
TEST(RigidWall, SpringForceAlongTheNormal)
{
  ContactNodes nodes;
  nodes.nodes = {particle(0, 0)};
  const double g = 1e-5;
  // Wall through (0, 0, 0) with normal (1, 1, 0)/sqrt(2); the node at depth g below it.
  const double s = 1 / std::sqrt(2.);
  set_state(nodes, {-g * s}, {0});
  nodes.state[1] = -g * s;
  InteractionSettings settings;
  settings.type_text = "rigid wall";
  settings.bodies    = {0};
  settings.penalty   = penalty;
  settings.point     = Vec3{{0, 0, 0}};
  settings.normal    = Vec3{{s, s, 0}};
  RigidWall  wall(settings);
  BondFilter bonds;
  bonds.reset(nodes);
  wall.reset(nodes);
  build_all(wall, nodes, bonds, spacing);
  std::vector<double> force(3, 0.);
  ForceSink           sink(force, 1e-3);
  wall.add_forces(nodes, 0, 1e-9, sink);
  const double k = penalty * bulk * spacing;
  EXPECT_NEAR(force[0], k * g * s, 1e-9 * k * g);
  EXPECT_NEAR(force[1], k * g * s, 1e-9 * k * g);
  EXPECT_EQ(force[2], 0.);
  EXPECT_NEAR(sink.wall_force, k * g, 1e-9 * k * g);
  EXPECT_NEAR(sink.stored, 0.5 * k * g * g, 1e-9 * k * g * g);
  // Critical step of the node on the wall spring: 2 sqrt(m / k).
  EXPECT_NEAR(wall.stable_dt(nodes), 2 * std::sqrt(mass / k), 1e-12);
}

// A slave pressed into the middle of a flat face: the spring s k (g - g0) along the face normal
// on the slave, g0 the depth at which its contact began (the entry offset), and a quarter of
// the reaction on each corner of the face (the forces balance).
TEST(NodeToSurface, SlaveOnAFaceGetsTheSpringAndTheCornersTheReaction)
{
  const double L     = 1e-2;
  ContactNodes nodes = face_and_slave(L);
  const auto  &face  = nodes.segments[0];
  NodeToSurface contact(surface_settings());
  contact.set_print_notices(false);
  contact.reset(nodes);
  BondFilter bonds;
  bonds.reset(nodes);
  place(nodes, 4, 1e-4); // above the face: no force
  build_all(contact, nodes, bonds, 0.1 * L);
  std::vector<double> force(3 * nodes.size(), 0.);
  {
    ForceSink sink(force, 1e-3);
    contact.add_forces(nodes, 0, 1e-9, sink);
    for (const double f : force)
      EXPECT_EQ(f, 0.);
  }
  // Enters g0 deep (no force: that depth is the offset), then pressed g deep.
  const double g0 = 1e-8, g = 1e-5;
  for (const double z : {-g0, -g})
    {
      place(nodes, 4, z);
      std::fill(force.begin(), force.end(), 0.);
      ForceSink sink(force, 1e-3);
      contact.add_forces(nodes, z == -g0 ? 1 : 2, 1e-9, sink);
      if (z == -g0)
        {
          for (const double f : force)
            EXPECT_EQ(f, 0.);
          continue;
        }
      const double fn = penalty * face.stiffness * (g - g0);
      EXPECT_NEAR(force[3 * 4 + 2], fn, 1e-6 * fn);
      EXPECT_NEAR(force[3 * 4 + 0], 0., 1e-9 * fn);
      for (unsigned int a = 0; a < 4; ++a)
        EXPECT_NEAR(force[3 * a + 2], -0.25 * fn, 1e-6 * fn);
      double sum = 0;
      for (unsigned int i = 0; i < nodes.size(); ++i)
        sum += force[3 * i + 2];
      EXPECT_NEAR(sum, 0., 1e-12 * fn);
      EXPECT_NEAR(sink.stored, 0.5 * fn * (g - g0), 1e-6 * fn * g);
    }
}

// Halo contact (issue 28): a pair is evaluated on one rank only. Node to surface: by the owner
// of the slave; the segment's nodes may be halo nodes (their reactions go back to their owners).
TEST(NodeToSurface, APairIsEvaluatedByTheOwnerOfItsSlave)
{
  const double L = 1e-2;
  for (const bool slave_owned : {true, false})
    {
      ContactNodes nodes = face_and_slave(L);
      for (unsigned int a = 0; a < 4; ++a)
        nodes.nodes[a].owned = false; // the face belongs to another rank
      nodes.nodes[4].owned = slave_owned;
      const auto &face     = nodes.segments[0];
      NodeToSurface contact(surface_settings());
      contact.set_print_notices(false);
      contact.reset(nodes);
      BondFilter bonds;
      bonds.reset(nodes);
      place(nodes, 4, 1e-4); // above the face at the build
      build_all(contact, nodes, bonds, 0.1 * L);
      double pressed = 0;
      // Enters 1e-8 deep (the entry offset), then pressed 1e-5 deep.
      for (const double z : {-1e-8, -1e-5})
        {
          nodes.state[ContactNodes::state_record * 4 + 2] = z;
          std::vector<double> force(3 * nodes.size(), 0.);
          ForceSink           sink(force, 1e-3);
          contact.add_forces(nodes, z == -1e-8 ? 1 : 2, 1e-9, sink);
          pressed = force[3 * 4 + 2];
          if (!slave_owned)
            {
              for (const double f : force)
                EXPECT_EQ(f, 0.);
            }
        }
      const double fn = penalty * face.stiffness * (1e-5 - 1e-8);
      if (slave_owned)
        {
          EXPECT_NEAR(pressed, fn, 1e-6 * fn);
        }
    }
}

// Particles: by the owner of the particle of smaller DOF (the node list is sorted by DOF).
TEST(ParticlePairs, APairIsEvaluatedByTheOwnerOfItsSmallerDof)
{
  for (const bool first_owned : {true, false})
    {
      ContactNodes nodes;
      nodes.nodes = {particle(0, 0), particle(0.99 * spacing, 1)};
      nodes.nodes[0].owned = first_owned;
      nodes.nodes[1].owned = !first_owned;
      set_state(nodes, {0, 0.99 * spacing}, {0, 0});
      BondFilter bonds;
      bonds.reset(nodes);
      bonds.sync({}, {0, 1});
      ParticlePairs pairs(particle_settings(0));
      pairs.reset(nodes);
      build_all(pairs, nodes, bonds, spacing);
      EXPECT_EQ(pairs.candidates().size(), first_owned ? 1u : 0u);
    }
}

// Ties (doc/manual/contact.md, "Ties"): a slave under the apex of a pyramid of four faces
// z = -s (|x| + |y|) (the nose point of the showcase projectile) is equally deep under all
// four. The face it keeps, and with it the direction of its force, must not depend on the
// order of the faces and nodes, which depends on the partition. Before the tie-break the first
// face found won: the three orders below pushed the slave along the normals of the faces of
// quadrants ++, +- and -- (checked: this test failed with that rule).
TEST(NodeToSurface, ATieBetweenFacesDoesNotDependOnTheirOrder)
{
  const double L = 1e-2, s = 0.3;
  // The apex, then the four edge midpoints and four corners of the base square (side 2L).
  const auto height = [&](const double x, const double y) { return -s * (std::abs(x) + std::abs(y)); };
  std::vector<Vec3> points = {{{0, 0, 0}}};
  for (const auto &xy : std::vector<std::array<double, 2>>{{{L, 0}}, {{0, L}}, {{-L, 0}}, {{0, -L}}, {{L, L}}, {{-L, L}}, {{-L, -L}}, {{L, -L}}})
    points.push_back(Vec3{{xy[0], xy[1], height(xy[0], xy[1])}});
  // The four faces, counter-clockwise seen from above (outside): quadrants ++, -+, --, +-.
  const std::vector<std::array<unsigned int, 4>> quadrants = {{{0, 1, 5, 2}}, {{0, 2, 6, 3}}, {{0, 3, 7, 4}}, {{0, 4, 8, 1}}};

  // The force on the slave with the target's nodes listed in @p node_order and its faces in
  // @p face_order.
  const auto slave_force = [&](const std::vector<unsigned int> &node_order, const std::vector<unsigned int> &face_order) {
    ContactNodes nodes;
    std::vector<unsigned int> index(points.size());
    for (unsigned int k = 0; k < node_order.size(); ++k)
      {
        index[node_order[k]] = k;
        ContactNode n;
        n.dof     = 3 * k;
        n.X       = points[node_order[k]];
        n.mass    = 1;
        n.bulk    = bulk;
        n.spacing = L;
        n.body    = 1;
        nodes.nodes.push_back(n);
      }
    ContactNode slave;
    slave.dof     = 3 * points.size();
    slave.mass    = 1;
    slave.bulk    = bulk;
    slave.spacing = L;
    slave.body    = 0;
    nodes.nodes.push_back(slave);
    const unsigned int i = static_cast<unsigned int>(points.size());
    for (const unsigned int f : face_order)
      {
        ContactSegment face;
        for (unsigned int v = 0; v < 4; ++v)
          face.node[v] = index[quadrants[f][v]];
        face.stiffness = bulk * L;
        face.body      = 1;
        nodes.segments.push_back(face);
      }
    NodeToSurface contact(surface_settings());
    contact.set_print_notices(false);
    contact.reset(nodes);
    BondFilter bonds;
    bonds.reset(nodes);
    place(nodes, i, 1e-4);
    build_all(contact, nodes, bonds, 0.1 * L);
    Vec3 f{};
    for (const double z : {-1e-8, -1e-5})
      {
        place(nodes, i, z);
        std::vector<double> force(3 * nodes.size(), 0.);
        ForceSink           sink(force, 1e-3);
        contact.add_forces(nodes, z == -1e-8 ? 1 : 2, 1e-9, sink);
        f = Vec3{{force[3 * i], force[3 * i + 1], force[3 * i + 2]}};
      }
    return f;
  };

  const Vec3 a = slave_force({0, 1, 2, 3, 4, 5, 6, 7, 8}, {0, 1, 2, 3});
  const Vec3 b = slave_force({8, 7, 6, 5, 4, 3, 2, 1, 0}, {3, 2, 1, 0});
  const Vec3 c = slave_force({4, 0, 7, 1, 6, 2, 5, 3, 8}, {2, 0, 3, 1});
  ASSERT_GT(a[2], 0.) << "the slave is pushed out";
  for (unsigned int d = 0; d < 3; ++d)
    {
      EXPECT_NEAR(b[d], a[d], 1e-12 * a[2]) << "component " << d;
      EXPECT_NEAR(c[d], a[d], 1e-12 * a[2]) << "component " << d;
    }
  // The tie goes to the face whose sorted reference positions come first: quadrant --, whose
  // outward normal is (-s, -s, 1) / sqrt(2 s^2 + 1).
  EXPECT_NEAR(a[0] / a[2], -s, 1e-9);
  EXPECT_NEAR(a[1] / a[2], -s, 1e-9);
}
