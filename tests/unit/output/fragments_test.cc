// SPDX-License-Identifier: LGPL-2.1-or-later
// Fragment size and shape (MassMoments, fragment_shape) and the debris classification
// (classify, summarize) against closed forms (doc/manual/failure.md, "Fragments").
#include <shard/output/fragments.h>

#include <gtest/gtest.h>

#include <cmath>
#include <random>

namespace
{
  using shard::output::Fragment;
  using shard::output::MassMoments;

  /// Nodes of a lattice of n[0] x n[1] x n[2] cubes of edge h, each of mass m, at x0 + Q (k h).
  MassMoments
  lattice(const std::array<unsigned int, 3> &n, const double h, const double m, const std::array<double, 3> &x0,
          const double (&Q)[3][3] = {{1, 0, 0}, {0, 1, 0}, {0, 0, 1}})
  {
    MassMoments moments;
    for (unsigned int i = 0; i < n[0]; ++i)
      for (unsigned int j = 0; j < n[1]; ++j)
        for (unsigned int k = 0; k < n[2]; ++k)
          {
            const double          r[3] = {i * h, j * h, k * h};
            std::array<double, 3> x    = x0;
            for (unsigned int a = 0; a < 3; ++a)
              for (unsigned int b = 0; b < 3; ++b)
                x[a] += Q[a][b] * r[b];
            moments.add(x, m, h * h * h);
          }
    return moments;
  }

  void
  random_rotation(std::mt19937 &gen, double (&Q)[3][3])
  {
    std::uniform_real_distribution<double> angle(0., 2. * M_PI);
    const double a = angle(gen), b = angle(gen), c = angle(gen);
    const double Rz[3][3] = {{std::cos(a), -std::sin(a), 0}, {std::sin(a), std::cos(a), 0}, {0, 0, 1}};
    const double Ry[3][3] = {{std::cos(b), 0, std::sin(b)}, {0, 1, 0}, {-std::sin(b), 0, std::cos(b)}};
    const double Rx[3][3] = {{1, 0, 0}, {0, std::cos(c), -std::sin(c)}, {0, std::sin(c), std::cos(c)}};
    double       T[3][3]  = {};
    for (int i = 0; i < 3; ++i)
      for (int j = 0; j < 3; ++j)
        for (int k = 0; k < 3; ++k)
          T[i][j] += Rz[i][k] * Ry[k][j];
    for (int i = 0; i < 3; ++i)
      for (int j = 0; j < 3; ++j)
        {
          Q[i][j] = 0;
          for (int k = 0; k < 3; ++k)
            Q[i][j] += T[i][k] * Rx[k][j];
        }
  }

  TEST(FragmentShape, SingleParticle)
  {
    // One cube of edge h: covariance (h^2 / 12) I, aspect ratio 1, d = (6 V / pi)^(1/3).
    MassMoments  m;
    const double V = 8e-9, h = 2e-3;
    m.add({{0.3, -1.2, 5.}}, 0.0628, V);
    const auto s = shard::output::fragment_shape(m);
    EXPECT_EQ(s.aspect_ratio, 1.);
    EXPECT_DOUBLE_EQ(s.volume, V);
    EXPECT_DOUBLE_EQ(s.equivalent_diameter, std::cbrt(6 * V / M_PI));
    for (const double l : s.principal_variances)
      EXPECT_NEAR(l, h * h / 12, 1e-15 * h * h);
  }

  TEST(FragmentShape, LatticeRod)
  {
    // n x 1 x 1 cubes: variances (n h)^2 / 12 along and h^2 / 12 across (the lattice variance
    // h^2 (n^2 - 1) / 12 plus the cubes' own h^2 / 12), so the aspect ratio is n exactly. Far
    // from the origin (1 km): the sums about the first node keep the small variance.
    const double h = 1e-3;
    for (unsigned int n = 1; n <= 40; ++n)
      {
        const auto s = shard::output::fragment_shape(lattice({{n, 1, 1}}, h, 7.85e-6, {{1e3, -2e3, 5e2}}));
        EXPECT_NEAR(s.aspect_ratio, n, 1e-9 * n) << n << " particles";
        EXPECT_NEAR(s.principal_variances[0], n * n * h * h / 12, 1e-9 * n * n * h * h);
        EXPECT_NEAR(s.principal_variances[2], h * h / 12, 1e-9 * h * h);
        EXPECT_NEAR(s.equivalent_diameter, std::cbrt(6 * n * h * h * h / M_PI), 1e-14);
      }
  }

  TEST(FragmentShape, LatticeBoxes)
  {
    // A box of a x b x c cubes, a >= b >= c: aspect ratio a / c (4 x 2 x 1: 4; 6 x 3 x 2: 3).
    EXPECT_NEAR(shard::output::fragment_shape(lattice({{4, 2, 1}}, 2e-3, 1., {{0., 0., 0.}})).aspect_ratio, 4., 1e-12);
    EXPECT_NEAR(shard::output::fragment_shape(lattice({{2, 1, 4}}, 2e-3, 1., {{0., 0., 0.}})).aspect_ratio, 4., 1e-12);
    EXPECT_NEAR(shard::output::fragment_shape(lattice({{6, 3, 2}}, 2e-3, 1., {{-1., 2., 3.}})).aspect_ratio, 3., 1e-12);
    EXPECT_NEAR(shard::output::fragment_shape(lattice({{3, 3, 3}}, 2e-3, 1., {{0., 0., 0.}})).aspect_ratio, 1., 1e-12);
  }

  TEST(FragmentShape, RotationInvariant)
  {
    // The same 5 x 3 x 2 box turned by random rotations: aspect ratio 2.5 and the same
    // principal variances (5 h)^2 / 12, (3 h)^2 / 12, (2 h)^2 / 12.
    std::mt19937 gen(26);
    const double h = 2e-3;
    for (int trial = 0; trial < 100; ++trial)
      {
        double Q[3][3];
        random_rotation(gen, Q);
        const auto s = shard::output::fragment_shape(lattice({{5, 3, 2}}, h, 3.14e-5, {{0.01, -0.02, 0.3}}, Q));
        EXPECT_NEAR(s.aspect_ratio, 2.5, 1e-12);
        EXPECT_NEAR(s.principal_variances[0], 25 * h * h / 12, 1e-12 * h * h);
        EXPECT_NEAR(s.principal_variances[1], 9 * h * h / 12, 1e-12 * h * h);
        EXPECT_NEAR(s.principal_variances[2], 4 * h * h / 12, 1e-12 * h * h);
      }
  }

  TEST(FragmentShape, MergeEqualsOnePass)
  {
    // The parts of a fragment on several "ranks" (each with its own reference point), merged in
    // any order, give the moments of one pass over all nodes; pack() and unpack() keep them.
    std::mt19937                           gen(3);
    std::uniform_real_distribution<double> u(-1., 1.);
    MassMoments                            all, part[3];
    for (int k = 0; k < 300; ++k)
      {
        const std::array<double, 3> x = {{5 + 0.01 * u(gen), -3 + 0.02 * u(gen), 0.001 * u(gen)}};
        const double                m = 1 + 0.5 * u(gen), V = 1e-9 * (1.5 + u(gen));
        all.add(x, m, V);
        part[(k * 7) % 3].add(x, m, V);
      }
    MassMoments a = part[2], b;
    a.merge(part[0]);
    a.merge(part[1]);
    b.merge(part[1]); // into an empty set: takes the other's reference
    b.merge(MassMoments());
    b.merge(part[2]);
    b.merge(part[0]);
    std::vector<double> packed;
    b.pack(packed);
    ASSERT_EQ(packed.size(), MassMoments::n_values);
    const MassMoments c = MassMoments::unpack(packed.data());
    const auto        C = all.covariance();
    for (const MassMoments *m : std::initializer_list<const MassMoments *>{&a, &b, &c})
      {
        EXPECT_NEAR(m->mass, all.mass, 1e-12 * all.mass);
        EXPECT_NEAR(m->volume, all.volume, 1e-12 * all.volume);
        const auto D = m->covariance();
        for (unsigned int k = 0; k < 6; ++k)
          EXPECT_NEAR(D[k], C[k], 1e-10 * C[0]) << k;
      }
    EXPECT_EQ(shard::output::fragment_shape(c).aspect_ratio, shard::output::fragment_shape(b).aspect_ratio);
  }

  TEST(FragmentShape, NoMass)
  {
    const auto s = shard::output::fragment_shape(MassMoments());
    EXPECT_EQ(s.aspect_ratio, 1.);
    EXPECT_EQ(s.equivalent_diameter, 0.);
  }

  Fragment
  fragment(const unsigned long long id, const unsigned int body, const unsigned long long nodes, const double mass,
           const std::array<double, 3> &v)
  {
    Fragment f;
    f.id = id, f.body = body, f.nodes = f.particles = nodes, f.mass = mass, f.velocity = v;
    return f;
  }

  TEST(FragmentClasses, DebrisDustConeAngle)
  {
    // Body 0: the heaviest (id 4) is the body; body 1: two of equal mass, the smaller id (2)
    // is the body. Dust: debris of fewer than 8 nodes.
    std::vector<Fragment> f = {fragment(1, 0, 7, 1., {{3., 0., -4.}}), fragment(2, 1, 50, 5., {{0., 0., 0.}}),
                               fragment(3, 1, 50, 5., {{0., 0., 2.}}), fragment(4, 0, 900, 9., {{0., 0., -1.}}),
                               fragment(5, 0, 8, 2., {{0., 1e-3, 0.}})};
    shard::output::classify(f, 8, {{0., 0., -1.}});
    const bool debris[5] = {true, false, true, false, true}, dust[5] = {true, false, false, false, false};
    for (unsigned int k = 0; k < 5; ++k)
      {
        EXPECT_EQ(f[k].debris, debris[k]) << f[k].id;
        EXPECT_EQ(f[k].dust, dust[k]) << f[k].id;
      }
    // atan2(|v x a|, v . a): (3, 0, -4) against -z: atan(3 / 4); at rest 0; +z against -z 180;
    // along the axis 0; across it 90.
    EXPECT_NEAR(f[0].cone_angle, std::atan(0.75) * 180 / M_PI, 1e-12);
    EXPECT_EQ(f[1].cone_angle, 0.);
    EXPECT_NEAR(f[2].cone_angle, 180., 1e-12);
    EXPECT_NEAR(f[3].cone_angle, 0., 1e-12);
    EXPECT_NEAR(f[4].cone_angle, 90., 1e-12);
    // Masses equal to round-off (1e-14 relative) are a tie: the smaller id is the body.
    std::vector<Fragment> halves = {fragment(7, 0, 225, 6.1544e-3 * (1 + 1e-14), {{0., 0., 1.}}),
                                    fragment(3, 0, 225, 6.1544e-3, {{0., 0., -1.}})};
    shard::output::classify(halves, 8, {{0., 0., -1.}});
    EXPECT_TRUE(halves[0].debris);
    EXPECT_FALSE(halves[1].debris);
    // One node is never dust at 'dust particles = 1'.
    shard::output::classify(f, 1, {{0., 0., -1.}});
    for (const auto &g : f)
      EXPECT_FALSE(g.dust);
  }

  TEST(FragmentClasses, Summary)
  {
    // One body of 10 kg and debris: dust 0.5 + 0.25 kg, coarse 1, 2, 4 kg (median 2); then
    // with a fourth coarse piece of 3 kg the median is (2 + 3) / 2.
    std::vector<Fragment> f = {fragment(1, 0, 1000, 10., {{0., 0., -1.}}), fragment(2, 0, 1, 0.5, {{0., 0., -30.}}),
                               fragment(3, 0, 2, 0.25, {{0., 40., 0.}}),      fragment(4, 0, 9, 1., {{0., 0., -2.}}),
                               fragment(5, 0, 20, 2., {{1., 0., -1.}}),       fragment(6, 0, 30, 4., {{0., 0., -3.}})};
    shard::output::classify(f, 8, {{0., 0., -1.}});
    auto s = shard::output::summarize(f);
    EXPECT_EQ(s.count, 6u);
    EXPECT_EQ(s.debris_count, 5u);
    EXPECT_EQ(s.dust_count, 2u);
    EXPECT_DOUBLE_EQ(s.mass, 17.75);
    EXPECT_DOUBLE_EQ(s.body_mass, 10.);
    EXPECT_DOUBLE_EQ(s.debris_mass, 7.75);
    EXPECT_DOUBLE_EQ(s.dust_mass, 0.75);
    EXPECT_DOUBLE_EQ(s.coarse_debris_mass, 7.);
    EXPECT_DOUBLE_EQ(s.body_mass + s.dust_mass + s.coarse_debris_mass, s.mass);
    EXPECT_DOUBLE_EQ(s.dust_fraction, 0.75 / 7.75);
    EXPECT_DOUBLE_EQ(s.coarse_debris_fraction, 7. / 7.75);
    EXPECT_DOUBLE_EQ(s.largest_debris_mass, 4.);
    EXPECT_DOUBLE_EQ(s.fastest_debris_speed, 40.);
    EXPECT_DOUBLE_EQ(s.median_coarse_debris_mass, 2.);
    // Angles: 0 (0.5 + 1 + 4 kg), 45 (2 kg), 90 (0.25 kg): mean (2 * 45 + 0.25 * 90) / 7.75;
    // 90 % of 7.75 kg = 6.975 kg is within 45 degrees (7.5 kg), not within 0 (5.5 kg).
    EXPECT_NEAR(s.cone_angle_mean, (2 * 45. + 0.25 * 90.) / 7.75, 1e-12);
    EXPECT_NEAR(s.cone_angle_90, 45., 1e-12);
    f.push_back(fragment(7, 0, 10, 3., {{0., 0., 0.}}));
    shard::output::classify(f, 8, {{0., 0., -1.}});
    s = shard::output::summarize(f);
    EXPECT_DOUBLE_EQ(s.median_coarse_debris_mass, 2.5);
    // No debris: every debris value 0.
    std::vector<Fragment> one = {fragment(9, 0, 100, 1., {{0., 0., 5.}})};
    shard::output::classify(one, 8, {{0., 0., -1.}});
    s = shard::output::summarize(one);
    EXPECT_EQ(s.debris_count, 0u);
    EXPECT_EQ(s.dust_fraction, 0.);
    EXPECT_EQ(s.cone_angle_90, 0.);
    EXPECT_EQ(s.median_coarse_debris_mass, 0.);
  }
} // namespace
