// SPDX-License-Identifier: LGPL-2.1-or-later
// Unit tests of the conversion geometry (include/shard/coupling/conversion.h): region tests
// against points placed by hand, and the corner Jacobian ratio against closed forms for
// affine maps and a folded corner. The conversion itself is tested by the scenes
// prm/verification/hybrid_patch and hybrid_conversion (doc/manual/hybrid.md).
#include <shard/coupling/conversion.h>

#include <gtest/gtest.h>

#include <cmath>
#include <stdexcept>

namespace
{
  using shard::coupling::min_corner_jacobian_ratio;
  using shard::coupling::Region;
  using shard::coupling::RegionParameters;
  using P = std::array<double, 3>;

  RegionParameters
  shape(const std::string &s)
  {
    RegionParameters p;
    p.shape = s;
    return p;
  }

  TEST(ConversionRegion, BoxIncludesItsFacesOnly)
  {
    auto p         = shape("box");
    p.lower_corner = "0, 0, 0";
    p.upper_corner = "1, 2, 3";
    const Region r(p, 0);
    EXPECT_TRUE(r.contains(P{{0.5, 1, 1.5}}));
    EXPECT_TRUE(r.contains(P{{1, 2, 3}}));
    EXPECT_FALSE(r.contains(P{{1.0001, 1, 1}}));
    EXPECT_FALSE(r.contains(P{{0.5, -0.0001, 1}}));
  }

  TEST(ConversionRegion, SphereAndCylinderAgainstDistances)
  {
    auto s   = shape("sphere");
    s.centre = "1, 1, 1";
    s.radius = 0.5;
    const Region sphere(s, 0);
    EXPECT_TRUE(sphere.contains(P{{1.3, 1.3, 1.2}})); // distance 0.469
    EXPECT_FALSE(sphere.contains(P{{1.3, 1.3, 1.27}})); // 0.503

    // Cylinder along (1, 1, 0) from the origin, radius 0.2, length sqrt(2).
    auto c      = shape("cylinder");
    c.centre    = "0, 0, 0";
    c.direction = "1, 1, 0";
    c.radius    = 0.2;
    c.length    = std::sqrt(2.);
    const Region cyl(c, 0);
    EXPECT_TRUE(cyl.contains(P{{0.5, 0.5, 0.19}}));
    EXPECT_FALSE(cyl.contains(P{{0.5, 0.5, 0.21}}));
    EXPECT_TRUE(cyl.contains(P{{0.95, 0.95, 0}}));   // along = 1.34 < 1.414
    EXPECT_FALSE(cyl.contains(P{{1.05, 1.05, 0}}));  // along = 1.48
    EXPECT_FALSE(cyl.contains(P{{-0.05, -0.05, 0}})); // behind the start face
  }

  TEST(ConversionRegion, HalfSpaceFollowsItsNormal)
  {
    auto h      = shape("half-space");
    h.centre    = "0, 0, 0.008";
    h.direction = "0, 0, -2"; // normalized inside
    const Region r(h, 3);
    EXPECT_EQ(r.body(), 3);
    EXPECT_TRUE(r.contains(P{{5, 5, 0.0079}}));
    EXPECT_TRUE(r.contains(P{{0, 0, 0.008}}));
    EXPECT_FALSE(r.contains(P{{0, 0, 0.0081}}));
  }

  TEST(ConversionRegion, BadGeometryIsRejected)
  {
    auto b         = shape("box");
    b.lower_corner = "0, 0, 0";
    b.upper_corner = "1, 0, 1";
    EXPECT_THROW(Region(b, 0), std::invalid_argument);
    auto s   = shape("sphere");
    s.radius = 0;
    EXPECT_THROW(Region(s, 0), std::invalid_argument);
    auto c      = shape("cylinder");
    c.radius    = 1;
    c.length    = 1;
    c.direction = "0, 0, 0";
    EXPECT_THROW(Region(c, 0), std::invalid_argument);
    auto h   = shape("half-space");
    h.centre = "1, 2";
    EXPECT_THROW(Region(h, 0), std::invalid_argument);
  }

  /// Unit cube in deal.II vertex order, mapped by x = A X.
  void
  affine(const double (&A)[3][3], double (&X)[8][3], double (&x)[8][3])
  {
    for (unsigned int v = 0; v < 8; ++v)
      {
        const double r[3] = {double(v & 1), double((v >> 1) & 1), double((v >> 2) & 1)};
        for (unsigned int i = 0; i < 3; ++i)
          {
            X[v][i] = r[i];
            x[v][i] = A[i][0] * r[0] + A[i][1] * r[1] + A[i][2] * r[2];
          }
      }
  }

  TEST(CornerJacobian, AffineMapGivesItsDeterminantAtEveryCorner)
  {
    const double A[3][3] = {{1.1, 0.2, 0.0}, {0.05, 0.9, 0.1}, {0.0, -0.3, 0.8}};
    const double det     = A[0][0] * (A[1][1] * A[2][2] - A[1][2] * A[2][1]) -
                       A[0][1] * (A[1][0] * A[2][2] - A[1][2] * A[2][0]) +
                       A[0][2] * (A[1][0] * A[2][1] - A[1][1] * A[2][0]);
    double X[8][3], x[8][3];
    affine(A, X, x);
    EXPECT_NEAR(min_corner_jacobian_ratio(x, X), det, 1e-14);
    // A rigid rotation keeps 1.
    const double c = std::cos(0.7), s = std::sin(0.7);
    const double R[3][3] = {{c, -s, 0}, {s, c, 0}, {0, 0, 1}};
    affine(R, X, x);
    EXPECT_NEAR(min_corner_jacobian_ratio(x, X), 1.0, 1e-14);
  }

  TEST(CornerJacobian, FoldedCornerIsNegative)
  {
    const double I[3][3] = {{1, 0, 0}, {0, 1, 0}, {0, 0, 1}};
    double       X[8][3], x[8][3];
    affine(I, X, x);
    // Push vertex 7 (1, 1, 1) through the opposite corner's plane: its corner Jacobian is
    // det[x6 - x7, x5 - x7, x3 - x7] with x7 = (-0.5, 1, 1) -> -(1.5) < 0.
    x[7][0] = -0.5;
    const double r = min_corner_jacobian_ratio(x, X);
    EXPECT_LT(r, 0.);
    EXPECT_NEAR(r, -0.5, 1e-14);
  }
} // namespace
