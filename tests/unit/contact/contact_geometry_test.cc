// SPDX-License-Identifier: LGPL-2.1-or-later
// Unit tests of the contact geometry kernels and the binned neighbour search
// (include/shard/contact/contact_geometry.h) against closed forms and brute force.
#include <shard/contact/contact_geometry.h>

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <map>
#include <random>
#include <stdexcept>
#include <vector>

namespace
{
  using namespace shard::contact;

  Vec3
  v3(const double x, const double y, const double z)
  {
    return Vec3{{x, y, z}};
  }

  Vec3
  sub(const Vec3 &a, const Vec3 &b)
  {
    return v3(a[0] - b[0], a[1] - b[1], a[2] - b[2]);
  }

  double
  dot3(const Vec3 &a, const Vec3 &b)
  {
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
  }

  Vec3
  cross3(const Vec3 &a, const Vec3 &b)
  {
    return v3(a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]);
  }

  double
  norm3(const Vec3 &a)
  {
    return std::sqrt(dot3(a, a));
  }

  /// A rigid motion x -> R x + t, R from axis-angle (Rodrigues).
  struct RigidMotion
  {
    double R[3][3];
    Vec3   t;

    RigidMotion(const Vec3 &axis, const double angle, const Vec3 &translation)
      : t(translation)
    {
      const double len = norm3(axis);
      const Vec3   u   = v3(axis[0] / len, axis[1] / len, axis[2] / len);
      const double c = std::cos(angle), s = std::sin(angle);
      for (unsigned int i = 0; i < 3; ++i)
        for (unsigned int j = 0; j < 3; ++j)
          R[i][j] = (i == j ? c : 0.0) + (1.0 - c) * u[i] * u[j];
      R[0][1] -= s * u[2];
      R[0][2] += s * u[1];
      R[1][0] += s * u[2];
      R[1][2] -= s * u[0];
      R[2][0] -= s * u[1];
      R[2][1] += s * u[0];
    }

    Vec3
    rotate(const Vec3 &x) const
    {
      Vec3 y{};
      for (unsigned int i = 0; i < 3; ++i)
        y[i] = R[i][0] * x[0] + R[i][1] * x[1] + R[i][2] * x[2];
      return y;
    }

    Vec3
    operator()(const Vec3 &x) const
    {
      const Vec3 y = rotate(x);
      return v3(y[0] + t[0], y[1] + t[1], y[2] + t[2]);
    }
  };

  std::array<Vec3, 4>
  unit_square()
  {
    return {{v3(0, 0, 0), v3(1, 0, 0), v3(1, 1, 0), v3(0, 1, 0)}};
  }

  /// sum_a w_a x_a
  Vec3
  weighted_point(const std::array<double, 4> &w, const std::array<Vec3, 4> &x)
  {
    Vec3 q{};
    for (unsigned int a = 0; a < 4; ++a)
      for (unsigned int k = 0; k < 3; ++k)
        q[k] += w[a] * x[a][k];
    return q;
  }

  void
  expect_valid_weights(const std::array<double, 4> &w, const double tol = 1e-14)
  {
    EXPECT_NEAR(w[0] + w[1] + w[2] + w[3], 1.0, tol);
    for (unsigned int a = 0; a < 4; ++a)
      EXPECT_GE(w[a], 0.0) << "node " << a;
  }

  void
  expect_vec_near(const Vec3 &a, const Vec3 &b, const double tol)
  {
    for (unsigned int k = 0; k < 3; ++k)
      EXPECT_NEAR(a[k], b[k], tol) << "component " << k;
  }
} // namespace


// ---------------------------------------------------------------- point_segment

TEST(ContactGeometry, PointSegmentUnitSquareInterior)
{
  const auto       x = unit_square();
  const SegmentHit r = point_segment(v3(0.3, 0.6, -0.01), x, 0.1);
  ASSERT_TRUE(r.hit);
  EXPECT_NEAR(r.gap, -0.01, 1e-14);
  expect_vec_near(r.normal, v3(0, 0, 1), 1e-15);
  expect_valid_weights(r.weights);
  // (0.3, 0.6) lies in the left triangle (x3, x0, c): q = 0.3 x3 + 0.1 x0 + 0.6 c, so the weights are
  // (0.1 + 0.15, 0.15, 0.15, 0.3 + 0.15).
  EXPECT_NEAR(r.weights[0], 0.25, 1e-14);
  EXPECT_NEAR(r.weights[1], 0.15, 1e-14);
  EXPECT_NEAR(r.weights[2], 0.15, 1e-14);
  EXPECT_NEAR(r.weights[3], 0.45, 1e-14);
  expect_vec_near(weighted_point(r.weights, x), v3(0.3, 0.6, 0.0), 1e-14);
}

TEST(ContactGeometry, PointSegmentMisses)
{
  const auto x = unit_square();
  // Above the segment (gap > 0): the projection is reported, but no hit.
  const SegmentHit above = point_segment(v3(0.3, 0.6, 0.01), x, 0.1);
  EXPECT_FALSE(above.hit);
  EXPECT_TRUE(above.projected);
  EXPECT_NEAR(above.gap, 0.01, 1e-14);
  // Deeper than max_depth: projected, no hit; beside the square: neither.
  EXPECT_TRUE(point_segment(v3(0.3, 0.6, -0.2), x, 0.1).projected);
  EXPECT_FALSE(point_segment(v3(1.5, 0.5, -0.01), x, 0.1).projected);
  EXPECT_TRUE(point_segment(v3(0.3, 0.6, -0.01), x, 0.1).projected);
  // Deeper than max_depth.
  EXPECT_FALSE(point_segment(v3(0.3, 0.6, -0.2), x, 0.1).hit);
  EXPECT_TRUE(point_segment(v3(0.3, 0.6, -0.09), x, 0.1).hit);
  // Outside the square.
  EXPECT_FALSE(point_segment(v3(1.5, 0.5, -0.01), x, 0.1).hit);
  EXPECT_FALSE(point_segment(v3(0.5, -0.01, -0.01), x, 0.1).hit);
  EXPECT_FALSE(point_segment(v3(-0.2, 1.2, -0.01), x, 0.1).hit);
  // Exactly on the surface: gap 0 is not a penetration.
  EXPECT_FALSE(point_segment(v3(0.3, 0.6, 0.0), x, 0.1).hit);
  // Clockwise node order flips the normal: the same point is then outside (gap > 0).
  const std::array<Vec3, 4> flipped = {{x[0], x[3], x[2], x[1]}};
  const SegmentHit          f       = point_segment(v3(0.3, 0.6, -0.01), flipped, 0.1);
  EXPECT_FALSE(f.hit);
  EXPECT_NEAR(f.gap, 0.01, 1e-14);
  expect_vec_near(f.normal, v3(0, 0, -1), 1e-15);
  // A fully degenerate segment never hits.
  const std::array<Vec3, 4> point_quad = {{v3(1, 1, 1), v3(1, 1, 1), v3(1, 1, 1), v3(1, 1, 1)}};
  EXPECT_FALSE(point_segment(v3(1, 1, 0.99), point_quad, 0.1).hit);
}

// The corner of a box: the end face z = 0 (outward normal -z) and the side face x = 1 (outward
// +x). A point just outside the end face (z = -1e-6, below it) and 0.4 inside the side face lies
// within the edge tolerance of the side face's lower edge: the side face reports a penetration
// of 0.4, the end face that the point is outside by 1e-6. Only the nearest of the two is the
// truth (the point is outside the box): Contact compares them (the nearest surface decides).
TEST(ContactGeometry, PointSegmentBoxCornerNearestSurface)
{
  // End face: the unit square seen from below (clockwise from above, normal -z).
  const auto                end  = unit_square();
  const std::array<Vec3, 4> down = {{end[0], end[3], end[2], end[1]}};
  // Side face x = 1 for 0 <= y <= 1, 0 <= z <= 1, counter-clockwise seen from +x.
  const std::array<Vec3, 4> side = {{v3(1, 0, 0), v3(1, 1, 0), v3(1, 1, 1), v3(1, 0, 1)}};
  const Vec3                p    = v3(0.6, 0.5, -1e-6);
  const SegmentHit          e    = point_segment(p, down, 1.0);
  EXPECT_FALSE(e.hit);
  EXPECT_TRUE(e.projected);
  EXPECT_NEAR(e.gap, 1e-6, 1e-15);
  const SegmentHit s = point_segment(p, side, 1.0);
  EXPECT_TRUE(s.hit);
  EXPECT_NEAR(s.gap, -0.4, 1e-14);
  expect_vec_near(s.normal, v3(1, 0, 0), 1e-15);
  EXPECT_LT(std::abs(e.gap), std::abs(s.gap));
  // Beyond the edge tolerance below the side face the side face no longer counts.
  EXPECT_FALSE(point_segment(v3(0.6, 0.5, -0.01), side, 1.0).projected);
}

TEST(ContactGeometry, PointSegmentEdgesAndCentroid)
{
  const auto x = unit_square();
  // Centroid: all weights 1/4.
  {
    const SegmentHit r = point_segment(v3(0.5, 0.5, -0.01), x, 0.1);
    ASSERT_TRUE(r.hit);
    EXPECT_NEAR(r.gap, -0.01, 1e-14);
    for (unsigned int a = 0; a < 4; ++a)
      EXPECT_NEAR(r.weights[a], 0.25, 1e-14);
    expect_valid_weights(r.weights);
  }
  // On the internal edge x0 - c: q = 0.5 x0 + 0.5 c, weights (0.625, 0.125, 0.125, 0.125).
  {
    const SegmentHit r = point_segment(v3(0.25, 0.25, -0.01), x, 0.1);
    ASSERT_TRUE(r.hit);
    EXPECT_NEAR(r.weights[0], 0.625, 1e-14);
    EXPECT_NEAR(r.weights[1], 0.125, 1e-14);
    EXPECT_NEAR(r.weights[2], 0.125, 1e-14);
    EXPECT_NEAR(r.weights[3], 0.125, 1e-14);
    expect_valid_weights(r.weights);
  }
  // On the outer edge x1 - x2 at y = 0.3: weights (0, 0.7, 0.3, 0).
  {
    const SegmentHit r = point_segment(v3(1.0, 0.3, -0.01), x, 0.1);
    ASSERT_TRUE(r.hit);
    EXPECT_NEAR(r.weights[0], 0.0, 1e-15);
    EXPECT_NEAR(r.weights[1], 0.7, 1e-14);
    EXPECT_NEAR(r.weights[2], 0.3, 1e-14);
    EXPECT_NEAR(r.weights[3], 0.0, 1e-15);
    expect_valid_weights(r.weights);
  }
  // At a node: all weight on that node.
  {
    const SegmentHit r = point_segment(v3(1.0, 1.0, -0.01), x, 0.1);
    ASSERT_TRUE(r.hit);
    EXPECT_NEAR(r.weights[2], 1.0, 1e-14);
    expect_valid_weights(r.weights);
  }
  // Slightly outside the outer edge x0 - x1, within the edge tolerance (barycentric -2e-5 > -1e-3):
  // hit, clamped to the edge, weights (0.5, 0.5, 0, 0).
  {
    const SegmentHit r = point_segment(v3(0.5, -1e-5, -0.01), x, 0.1);
    ASSERT_TRUE(r.hit);
    EXPECT_NEAR(r.weights[0], 0.5, 1e-14);
    EXPECT_NEAR(r.weights[1], 0.5, 1e-14);
    EXPECT_EQ(r.weights[2], 0.0);
    EXPECT_EQ(r.weights[3], 0.0);
    expect_valid_weights(r.weights);
    // With zero tolerance it is outside.
    EXPECT_FALSE(point_segment(v3(0.5, -1e-5, -0.01), x, 0.1, 0.0).hit);
  }
}

TEST(ContactGeometry, PointSegmentRotatedTranslated)
{
  const auto          x = unit_square();
  const RigidMotion   m(v3(0.3, -1.1, 0.7), 2.1, v3(1.5, -2.0, 0.7));
  std::array<Vec3, 4> y;
  for (unsigned int a = 0; a < 4; ++a)
    y[a] = m(x[a]);
  const Vec3 points[] = {v3(0.3, 0.6, -0.01), v3(0.8, 0.1, -0.03), v3(0.5, 0.5, -0.002), v3(0.9, 0.75, -0.05)};
  for (const Vec3 &p : points)
    {
      const SegmentHit r0 = point_segment(p, x, 0.1);
      const SegmentHit r1 = point_segment(m(p), y, 0.1);
      ASSERT_TRUE(r1.hit);
      EXPECT_NEAR(r1.gap, p[2], 1e-14);
      expect_vec_near(r1.normal, m.rotate(v3(0, 0, 1)), 1e-14);
      for (unsigned int a = 0; a < 4; ++a)
        EXPECT_NEAR(r1.weights[a], r0.weights[a], 1e-14);
      // q = p - gap n is the image of the planar projection (p_x, p_y, 0).
      expect_vec_near(weighted_point(r1.weights, y), m(v3(p[0], p[1], 0.0)), 1e-14);
    }
}

TEST(ContactGeometry, PointSegmentMomentBalanceNonPlanar)
{
  std::mt19937                           rng(42);
  std::uniform_real_distribution<double> u01(0.0, 1.0);
  std::uniform_real_distribution<double> dz(-0.02, 0.02);
  unsigned int                           n_checked = 0;
  for (unsigned int sample = 0; sample < 400; ++sample)
    {
      // Unit square with random node heights (not planar), then a random rigid motion.
      std::array<Vec3, 4> x0 = unit_square();
      for (auto &node : x0)
        node[2] = dz(rng);
      const double s = 0.05 + 0.9 * u01(rng), t = 0.05 + 0.9 * u01(rng);
      // Keep away from the internal edges, where a projection can clamp onto a neighbour triangle.
      if (std::abs(s - t) < 0.02 || std::abs(s + t - 1.0) < 0.02)
        continue;
      // Triangle of the centroid split that contains (s, t) in plan view: 0 bottom, 1 right, 2 top, 3 left.
      unsigned int tri;
      if (t < s && t < 1.0 - s)
        tri = 0;
      else if (t < s)
        tri = 1;
      else if (t > 1.0 - s)
        tri = 2;
      else
        tri = 3;
      const double z_bilinear = (1 - s) * (1 - t) * x0[0][2] + s * (1 - t) * x0[1][2] + s * t * x0[2][2] +
                                (1 - s) * t * x0[3][2];
      const Vec3 p0 = v3(s, t, z_bilinear - 0.03);

      const RigidMotion   m(v3(u01(rng) - 0.5, u01(rng) - 0.5, u01(rng) - 0.5), 6.0 * u01(rng),
                          v3(4 * u01(rng) - 2, 4 * u01(rng) - 2, 4 * u01(rng) - 2));
      std::array<Vec3, 4> x;
      for (unsigned int a = 0; a < 4; ++a)
        x[a] = m(x0[a]);
      const Vec3       p = m(p0);
      const SegmentHit r = point_segment(p, x, 1.0);
      ASSERT_TRUE(r.hit) << "sample " << sample;
      ++n_checked;

      // Closed form of the expected triangle (x_tri, x_tri+1, c).
      Vec3 c{};
      for (unsigned int a = 0; a < 4; ++a)
        for (unsigned int k = 0; k < 3; ++k)
          c[k] += 0.25 * x[a][k];
      const Vec3 &xa = x[tri];
      const Vec3 &xb = x[(tri + 1) % 4];
      Vec3        n  = cross3(sub(xb, xa), sub(c, xa));
      const double len = norm3(n);
      for (double &v : n)
        v /= len;
      expect_vec_near(r.normal, n, 1e-13);
      EXPECT_NEAR(r.gap, dot3(sub(p, xa), n), 1e-14);

      expect_valid_weights(r.weights);
      // sum_a w_a x_a = q = p - gap n.
      const Vec3 q  = v3(p[0] - r.gap * r.normal[0], p[1] - r.gap * r.normal[1], p[2] - r.gap * r.normal[2]);
      const Vec3 qw = weighted_point(r.weights, x);
      expect_vec_near(qw, q, 1e-14);

      // A normal force f on the slave at p and -w_a f on the nodes: zero resultant and zero moment
      // about the origin.
      const double F = 1.0e3 * (0.5 + u01(rng));
      const Vec3   f = v3(F * r.normal[0], F * r.normal[1], F * r.normal[2]);
      Vec3         force = f;
      Vec3         moment = cross3(p, f);
      for (unsigned int a = 0; a < 4; ++a)
        {
          const Vec3 fa = v3(-r.weights[a] * f[0], -r.weights[a] * f[1], -r.weights[a] * f[2]);
          const Vec3 ma = cross3(x[a], fa);
          for (unsigned int k = 0; k < 3; ++k)
            {
              force[k] += fa[k];
              moment[k] += ma[k];
            }
        }
      expect_vec_near(force, v3(0, 0, 0), 1e-11 * F);
      expect_vec_near(moment, v3(0, 0, 0), 1e-12 * F * 10.0);
    }
  EXPECT_GT(n_checked, 300u);
}

TEST(ContactGeometry, PointSegmentFoldedPicksSmallestGap)
{
  // Saddle: x0 and x2 raised by 0.4, centroid (0.5, 0.5, 0.2). The point projects onto both the
  // bottom triangle (x0, x1, c) and the left triangle (x3, x0, c); the left one is closer. The right
  // and top triangles have even smaller |gap| but the projection falls outside them.
  const std::array<Vec3, 4> x = {{v3(0, 0, 0.4), v3(1, 0, 0), v3(1, 1, 0.4), v3(0, 1, 0)}};
  const Vec3                c = v3(0.5, 0.5, 0.2);
  // Signed distance of p from the plane of the triangle (a, b, c); n receives its unit normal.
  const auto plane = [&](const Vec3 &a, const Vec3 &b, const Vec3 &p, Vec3 &n) {
    n                = cross3(sub(b, a), sub(c, a));
    const double len = norm3(n);
    for (double &v : n)
      v /= len;
    return dot3(sub(p, a), n);
  };
  Vec3 n_bottom, n_left, n_right, n_top;

  const Vec3   p          = v3(0.05, 0.15, -0.1);
  const double gap_bottom = plane(x[0], x[1], p, n_bottom);
  const double gap_left   = plane(x[3], x[0], p, n_left);
  const double gap_right  = plane(x[1], x[2], p, n_right);
  const double gap_top    = plane(x[2], x[3], p, n_top);
  ASSERT_LT(std::abs(gap_left), std::abs(gap_bottom) - 0.03);
  ASSERT_LT(std::abs(gap_right), std::abs(gap_left));
  ASSERT_LT(std::abs(gap_top), std::abs(gap_left));
  const SegmentHit r = point_segment(p, x, 1.0);
  ASSERT_TRUE(r.hit);
  EXPECT_NEAR(r.gap, gap_left, 1e-14);
  expect_vec_near(r.normal, n_left, 1e-14);
  expect_valid_weights(r.weights);
  expect_vec_near(weighted_point(r.weights, x), v3(p[0] - r.gap * r.normal[0], p[1] - r.gap * r.normal[1],
                                                   p[2] - r.gap * r.normal[2]),
                  1e-14);

  // Mirror image about x = y: now the bottom triangle is the closer one.
  const Vec3       pm = v3(0.15, 0.05, -0.1);
  const SegmentHit rm = point_segment(pm, x, 1.0);
  ASSERT_TRUE(rm.hit);
  EXPECT_NEAR(rm.gap, plane(x[0], x[1], pm, n_bottom), 1e-14);
  EXPECT_NEAR(rm.gap, gap_left, 1e-14);
  expect_vec_near(rm.normal, n_bottom, 1e-14);
  // The closer triangle decides the hit: within max_depth of it, but not of the farther one.
  EXPECT_TRUE(point_segment(p, x, 0.42).hit);
}

// ---------------------------------------------------------------- sphere_pair, plane_gap

TEST(ContactGeometry, SpherePair)
{
  // |xj - xi| = 5 along (0.6, 0.8, 0).
  const Vec3      xi = v3(1, 2, 3), xj = v3(4, 6, 3);
  const SphereHit a  = sphere_pair(xi, xj, 3.0, 2.5);
  EXPECT_NEAR(a.overlap, 0.5, 1e-14);
  expect_vec_near(a.normal, v3(0.6, 0.8, 0.0), 1e-15);
  // Reversed pair: same overlap, opposite normal.
  const SphereHit b = sphere_pair(xj, xi, 2.5, 3.0);
  EXPECT_NEAR(b.overlap, 0.5, 1e-14);
  expect_vec_near(b.normal, v3(-0.6, -0.8, 0.0), 1e-15);
  // Separated: negative overlap.
  EXPECT_NEAR(sphere_pair(xi, xj, 1.0, 1.5).overlap, -2.5, 1e-14);
  // Touching.
  EXPECT_NEAR(sphere_pair(v3(0, 0, 0), v3(0, 0, -2), 1.25, 0.75).overlap, 0.0, 1e-15);
  expect_vec_near(sphere_pair(v3(0, 0, 0), v3(0, 0, -2), 1.25, 0.75).normal, v3(0, 0, -1), 0.0);
  // Coincident centres.
  const SphereHit c = sphere_pair(xi, xi, 0.3, 0.2);
  EXPECT_EQ(c.overlap, 0.5);
  EXPECT_EQ(c.normal[0], 0.0);
  EXPECT_EQ(c.normal[1], 0.0);
  EXPECT_EQ(c.normal[2], 0.0);
}

TEST(ContactGeometry, PlaneGap)
{
  // Plane through (1, 1, 1) with normal (0, 0.6, 0.8).
  const Vec3 o = v3(1, 1, 1), n = v3(0, 0.6, 0.8);
  EXPECT_NEAR(plane_gap(v3(5, 2, 3), o, n), 0.6 * 1 + 0.8 * 2, 1e-15);
  EXPECT_NEAR(plane_gap(v3(-3, 0, -1), o, n), 0.6 * -1 + 0.8 * -2, 1e-15);
  // Points in the plane (any tangential offset) have zero gap.
  EXPECT_NEAR(plane_gap(v3(7, 1 + 0.8, 1 - 0.6), o, n), 0.0, 1e-15);
  EXPECT_EQ(plane_gap(o, o, n), 0.0);
}

// ---------------------------------------------------------------- coulomb_friction

TEST(ContactGeometry, CoulombFrictionSliding)
{
  // v_t = (3, 4, 0), |v_t| = 5 >> v_eps: f = -mu fn (0.6, 0.8, 0).
  const Vec3 f = coulomb_friction(v3(3, 4, 7), v3(0, 0, 1), 10.0, 0.3, 1e-6);
  expect_vec_near(f, v3(-1.8, -2.4, 0.0), 1e-14);
  // Normal-only relative velocity: no friction.
  expect_vec_near(coulomb_friction(v3(0, 0, -5), v3(0, 0, 1), 10.0, 0.3, 1e-6), v3(0, 0, 0), 0.0);
  // Zero normal force or zero mu: no friction; a negative normal force counts as zero.
  expect_vec_near(coulomb_friction(v3(3, 4, 7), v3(0, 0, 1), 0.0, 0.3, 1e-6), v3(0, 0, 0), 0.0);
  expect_vec_near(coulomb_friction(v3(3, 4, 7), v3(0, 0, 1), 10.0, 0.0, 1e-6), v3(0, 0, 0), 0.0);
  expect_vec_near(coulomb_friction(v3(3, 4, 7), v3(0, 0, 1), -10.0, 0.3, 1e-6), v3(0, 0, 0), 0.0);
  // Tilted normal: magnitude mu fn, direction -v_t / |v_t|.
  const Vec3   n  = v3(0, 0.6, 0.8);
  const Vec3   v  = v3(2, -1, 4);
  const double vn = dot3(v, n);
  const Vec3   vt = v3(v[0] - vn * n[0], v[1] - vn * n[1], v[2] - vn * n[2]);
  const Vec3   g  = coulomb_friction(v, n, 50.0, 0.4, 1e-3);
  const double s  = 0.4 * 50.0 / norm3(vt);
  expect_vec_near(g, v3(-s * vt[0], -s * vt[1], -s * vt[2]), 1e-13);
  EXPECT_NEAR(norm3(g), 20.0, 1e-13);
}

TEST(ContactGeometry, CoulombFrictionRegularizedBelowVeps)
{
  // |v_t| = 5e-7 < v_eps = 1e-3: f = -mu fn v_t / v_eps, linear in v_t.
  const Vec3 f = coulomb_friction(v3(3e-7, 4e-7, 2), v3(0, 0, 1), 10.0, 0.3, 1e-3);
  expect_vec_near(f, v3(-9e-4, -1.2e-3, 0.0), 1e-17);
  const Vec3 f2 = coulomb_friction(v3(6e-7, 8e-7, 2), v3(0, 0, 1), 10.0, 0.3, 1e-3);
  expect_vec_near(f2, v3(2 * f[0], 2 * f[1], 0.0), 1e-17);
  // Continuity at |v_t| = v_eps: magnitude mu fn from both sides.
  EXPECT_NEAR(norm3(coulomb_friction(v3(1e-3, 0, 1), v3(0, 0, 1), 10.0, 0.3, 1e-3)), 3.0, 1e-14);
  EXPECT_NEAR(norm3(coulomb_friction(v3(0.999e-3, 0, 1), v3(0, 0, 1), 10.0, 0.3, 1e-3)), 3.0 * 0.999, 1e-12);
}

TEST(ContactGeometry, CoulombFrictionRandomTangentialAndDissipative)
{
  std::mt19937                           rng(7);
  std::normal_distribution<double>       gauss(0.0, 1.0);
  std::uniform_real_distribution<double> u01(0.0, 1.0);
  for (unsigned int sample = 0; sample < 1000; ++sample)
    {
      Vec3         n   = v3(gauss(rng), gauss(rng), gauss(rng));
      const double len = norm3(n);
      for (double &v : n)
        v /= len;
      const Vec3   v_rel = v3(20 * u01(rng) - 10, 20 * u01(rng) - 10, 20 * u01(rng) - 10);
      const double fn    = 1000.0 * u01(rng);
      const double mu    = u01(rng);
      const double v_eps = std::pow(10.0, -4.0 + 5.0 * u01(rng));
      const Vec3   f     = coulomb_friction(v_rel, n, fn, mu, v_eps);

      // Reference tangential velocity and f . n in long double (no rounding of the test itself).
      const long double vn = static_cast<long double>(v_rel[0]) * n[0] + static_cast<long double>(v_rel[1]) * n[1] +
                             static_cast<long double>(v_rel[2]) * n[2];
      long double vt[3], vt2 = 0, f_dot_n = 0, f_dot_vt = 0, f2 = 0;
      for (unsigned int k = 0; k < 3; ++k)
        {
          vt[k] = v_rel[k] - vn * n[k];
          vt2 += vt[k] * vt[k];
          f_dot_n += static_cast<long double>(f[k]) * n[k];
          f2 += static_cast<long double>(f[k]) * f[k];
        }
      for (unsigned int k = 0; k < 3; ++k)
        f_dot_vt += static_cast<long double>(f[k]) * vt[k];
      const double speed = static_cast<double>(std::sqrt(vt2));

      EXPECT_LE(std::abs(static_cast<double>(f_dot_n)), 1e-15 * mu * fn) << "sample " << sample;
      EXPECT_LE(static_cast<double>(f_dot_vt), 0.0) << "sample " << sample;
      EXPECT_NEAR(static_cast<double>(std::sqrt(f2)), mu * fn * std::min(1.0, speed / v_eps), 1e-12 * mu * fn)
        << "sample " << sample;
    }
}

// ---------------------------------------------------------------- BinGrid

namespace
{
  std::vector<unsigned int>
  brute_force(const std::vector<Vec3> &points, const Vec3 &lo, const Vec3 &hi)
  {
    std::vector<unsigned int> result;
    for (unsigned int i = 0; i < points.size(); ++i)
      {
        bool inside = true;
        for (unsigned int k = 0; k < 3; ++k)
          inside = inside && lo[k] <= points[i][k] && points[i][k] <= hi[k];
        if (inside)
          result.push_back(i);
      }
    return result;
  }

  std::vector<unsigned int>
  query(const BinGrid &grid, const Vec3 &lo, const Vec3 &hi)
  {
    std::vector<unsigned int> result;
    grid.for_each_in_box(lo, hi, [&](const unsigned int i) { result.push_back(i); });
    return result;
  }

  /// 2000 random points in [-1, 2] x [0, 1] x [5, 5.5] with some exact duplicates.
  std::vector<Vec3>
  random_points(const unsigned int seed, const bool flat = false)
  {
    std::mt19937                           rng(seed);
    std::uniform_real_distribution<double> u01(0.0, 1.0);
    std::vector<Vec3>                      points(2000);
    for (unsigned int i = 0; i < points.size(); ++i)
      {
        points[i] = v3(-1.0 + 3.0 * u01(rng), u01(rng), flat ? 5.0 : 5.0 + 0.5 * u01(rng));
        if (i % 50 == 49)
          points[i] = points[i - 7];
      }
    return points;
  }

  /// Compares 200 random box queries (plus boxes with corners exactly at point coordinates) with brute force.
  void
  check_against_brute_force(const BinGrid &grid, const std::vector<Vec3> &points, const unsigned int seed)
  {
    std::mt19937                           rng(seed);
    std::uniform_real_distribution<double> u01(0.0, 1.0);
    std::size_t                            n_found = 0;
    for (unsigned int q = 0; q < 200; ++q)
      {
        Vec3 lo{}, hi{};
        if (q % 4 == 3)
          {
            // Corners exactly at two point coordinates: inclusive bounds matter.
            const Vec3 &a = points[static_cast<std::size_t>(u01(rng) * points.size())];
            const Vec3 &b = points[static_cast<std::size_t>(u01(rng) * points.size())];
            for (unsigned int k = 0; k < 3; ++k)
              {
                lo[k] = std::min(a[k], b[k]);
                hi[k] = std::max(a[k], b[k]);
              }
          }
        else
          {
            const Vec3 box_lo = v3(-1.5, -0.5, 4.8), box_len = v3(4.0, 2.0, 1.0);
            for (unsigned int k = 0; k < 3; ++k)
              {
                const double c = box_lo[k] + box_len[k] * u01(rng);
                const double h = 0.3 * box_len[k] * u01(rng) * u01(rng);
                lo[k]          = c - h;
                hi[k]          = c + h;
              }
          }
        const std::vector<unsigned int> expected = brute_force(points, lo, hi);
        EXPECT_EQ(query(grid, lo, hi), expected) << "query " << q;
        n_found += expected.size();
      }
    EXPECT_GT(n_found, 1000u); // the queries are not all empty
  }
} // namespace

TEST(BinGrid, MatchesBruteForceRandomBoxes)
{
  const std::vector<Vec3> points = random_points(3);
  BinGrid                 grid;
  grid.build(points, 0.1);
  EXPECT_EQ(grid.size(), 2000u);
  EXPECT_EQ(grid.cell_size(), 0.1);
  EXPECT_LE(grid.n_cells(), 8u * 2000u + 64u);
  check_against_brute_force(grid, points, 11);
  // A box around everything finds every point once, in index order.
  std::vector<unsigned int> all(2000);
  for (unsigned int i = 0; i < all.size(); ++i)
    all[i] = i;
  EXPECT_EQ(query(grid, v3(-10, -10, -10), v3(10, 10, 10)), all);
  // An inverted box finds nothing.
  EXPECT_TRUE(query(grid, v3(1, 0.5, 5.3), v3(0, 0.6, 5.4)).empty());

  // Rebuilding with other points replaces the content.
  const std::vector<Vec3> other = random_points(5, true);
  grid.build(other, 0.23);
  EXPECT_EQ(grid.size(), 2000u);
  check_against_brute_force(grid, other, 13);
}

TEST(BinGrid, NestedQueries)
{
  const std::vector<Vec3> points = random_points(17);
  BinGrid                 grid;
  grid.build(points, 0.2);
  const Vec3                lo = v3(0, 0.2, 5.1), hi = v3(0.5, 0.7, 5.4);
  std::vector<unsigned int> outer;
  std::size_t               n_inner = 0;
  grid.for_each_in_box(lo, hi, [&](const unsigned int i) {
    outer.push_back(i);
    const Vec3 &x  = points[i];
    const Vec3  l2 = v3(x[0] - 0.1, x[1] - 0.1, x[2] - 0.1), h2 = v3(x[0] + 0.1, x[1] + 0.1, x[2] + 0.1);
    const std::vector<unsigned int> inner = query(grid, l2, h2);
    EXPECT_EQ(inner, brute_force(points, l2, h2));
    n_inner += inner.size();
  });
  EXPECT_EQ(outer, brute_force(points, lo, hi));
  EXPECT_FALSE(outer.empty());
  EXPECT_GT(n_inner, outer.size());
}

TEST(BinGrid, TinyCellSizeIsCapped)
{
  for (const bool flat : {false, true})
    {
      const std::vector<Vec3> points = random_points(23, flat);
      BinGrid                 grid;
      grid.build(points, 1e-9);
      EXPECT_LE(grid.n_cells(), 8u * 2000u + 64u);
      EXPECT_GT(grid.n_cells(), 100u); // still a real grid, not a single cell
      EXPECT_GT(grid.cell_size(), 1e-9);
      check_against_brute_force(grid, points, 29);
    }
  // Extreme requested size: still capped and exact.
  const std::vector<Vec3> points = random_points(31);
  BinGrid                 grid;
  grid.build(points, std::numeric_limits<double>::denorm_min());
  EXPECT_LE(grid.n_cells(), 8u * 2000u + 64u);
  check_against_brute_force(grid, points, 37);
  // A cell much larger than the box: one cell.
  grid.build(points, 100.0);
  EXPECT_EQ(grid.n_cells(), 1u);
  check_against_brute_force(grid, points, 41);
}

TEST(BinGrid, SinglePoint)
{
  BinGrid    grid;
  const Vec3 p = v3(0.25, -3.5, 7.0);
  grid.build({p}, 0.5);
  EXPECT_EQ(grid.size(), 1u);
  EXPECT_EQ(grid.n_cells(), 1u);
  EXPECT_EQ(query(grid, p, p), std::vector<unsigned int>{0u});
  EXPECT_EQ(query(grid, v3(0, -4, 6), v3(1, -3, 8)), std::vector<unsigned int>{0u});
  EXPECT_EQ(query(grid, v3(0.25, -3.5, 7.0), v3(9, 9, 9)), std::vector<unsigned int>{0u});
  EXPECT_TRUE(query(grid, v3(0.2500001, -4, 6), v3(1, -3, 8)).empty());
  EXPECT_TRUE(query(grid, v3(0, -4, 6), v3(0.2499999, -3, 8)).empty());
  EXPECT_TRUE(query(grid, v3(0, -4, 7.5), v3(1, -3, 8)).empty());
}

TEST(BinGrid, EmptyAndInvalid)
{
  BinGrid grid;
  EXPECT_EQ(grid.size(), 0u);
  EXPECT_TRUE(query(grid, v3(-1, -1, -1), v3(1, 1, 1)).empty());
  grid.build({}, 1.0);
  EXPECT_EQ(grid.size(), 0u);
  EXPECT_TRUE(query(grid, v3(-1, -1, -1), v3(1, 1, 1)).empty());

  const std::vector<Vec3> points = {v3(0, 0, 0), v3(1, 1, 1)};
  EXPECT_THROW(grid.build(points, 0.0), std::invalid_argument);
  EXPECT_THROW(grid.build(points, -1.0), std::invalid_argument);
  EXPECT_THROW(grid.build(points, std::numeric_limits<double>::quiet_NaN()), std::invalid_argument);
  EXPECT_THROW(grid.build(points, std::numeric_limits<double>::infinity()), std::invalid_argument);
  const std::vector<Vec3> bad = {v3(0, 0, 0), v3(std::numeric_limits<double>::quiet_NaN(), 1, 1)};
  EXPECT_THROW(grid.build(bad, 1.0), std::invalid_argument);
}

TEST(BinGrid, NeighbourPairsCoverEveryCloserPairOnce)
{
  // Every pair closer than the cell edge is visited exactly once, whatever the cell size the
  // cap leaves (a flat cloud with duplicate points, two cell sizes, one of them capped).
  for (const bool flat : {false, true})
    for (const double h : {0.1, 1e-4})
      {
        const std::vector<Vec3> points = random_points(flat ? 23 : 29, flat);
        BinGrid                 grid;
        grid.build(points, h);
        const double                                          reach = grid.cell_size();
        std::map<std::pair<unsigned int, unsigned int>, int> seen;
        grid.for_each_neighbour_pair([&](const unsigned int i, const unsigned int j) {
          ASSERT_NE(i, j);
          ++seen[{std::min(i, j), std::max(i, j)}];
        });
        std::size_t n_close = 0;
        for (unsigned int i = 0; i < points.size(); ++i)
          for (unsigned int j = i + 1; j < points.size(); ++j)
            {
              double d2 = 0;
              for (unsigned int k = 0; k < 3; ++k)
                d2 += (points[i][k] - points[j][k]) * (points[i][k] - points[j][k]);
              if (d2 < reach * reach)
                {
                  ++n_close;
                  const auto it = seen.find({i, j});
                  ASSERT_TRUE(it != seen.end()) << "pair " << i << ", " << j << " at " << std::sqrt(d2);
                }
            }
        for (const auto &[pair, count] : seen)
          EXPECT_EQ(count, 1) << "pair " << pair.first << ", " << pair.second;
        EXPECT_GT(n_close, 100u); // not a vacuous check
      }
  BinGrid empty;
  empty.build({}, 1.0);
  bool visited = false;
  empty.for_each_neighbour_pair([&](unsigned int, unsigned int) { visited = true; });
  EXPECT_FALSE(visited);
}
