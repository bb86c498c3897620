// SPDX-License-Identifier: LGPL-2.1-or-later
// Unit tests of the reproducing-kernel shape functions and the binned neighbour search
// (include/shard/particles/rk_shape.h, neighbor_build.h) against closed forms, lattice geometry,
// finite differences and computations written out here (doc/theory/rk_shape_functions.md, "Tests").
#include <shard/particles/neighbor_build.h>
#include <shard/particles/rk_shape.h>

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <random>
#include <stdexcept>
#include <string>
#include <vector>

namespace
{
  using namespace shard::particles;

  /// The cubic B-spline written out as in formulation.md section 2 (expanded polynomials).
  double
  ref_phi(const double z)
  {
    if (z <= 0.5)
      return 2.0 / 3.0 - 4.0 * z * z + 4.0 * z * z * z;
    if (z <= 1.0)
      return 4.0 / 3.0 - 4.0 * z + 4.0 * z * z - 4.0 / 3.0 * z * z * z;
    return 0.0;
  }

  double
  ref_dphi(const double z)
  {
    if (z <= 0.5)
      return -8.0 * z + 12.0 * z * z;
    if (z <= 1.0)
      return -4.0 + 8.0 * z - 4.0 * z * z;
    return 0.0;
  }

  /// Kernel of the test: box = product of 1-D splines; sphere = spline of |r|/a (equal radii).
  double
  ref_kernel(const Point3 &r, const Point3 &a, const Support support)
  {
    if (support == Support::box)
      return ref_phi(std::abs(r[0]) / a[0]) * ref_phi(std::abs(r[1]) / a[1]) * ref_phi(std::abs(r[2]) / a[2]);
    return ref_phi(std::sqrt(r[0] * r[0] + r[1] * r[1] + r[2] * r[2]) / a[0]);
  }

  Point3
  pt(const double x, const double y, const double z)
  {
    return Point3{{x, y, z}};
  }

  struct Cloud
  {
    std::vector<Point3> x;
    std::vector<Point3> a;
  };

  /// A lattice of n[0] x n[1] x n[2] particles, spacing h, origin o, each component perturbed by
  /// a uniform value in [-perturbation, perturbation] (seeded), radii a = c h.
  Cloud
  lattice(const unsigned int (&n)[3], const double h, const Point3 &o, const double c,
          const double perturbation = 0.0, const unsigned int seed = 1)
  {
    std::mt19937                           rng(seed);
    std::uniform_real_distribution<double> u(-perturbation, perturbation);
    Cloud                                  cl;
    for (unsigned int k = 0; k < n[2]; ++k)
      for (unsigned int j = 0; j < n[1]; ++j)
        for (unsigned int i = 0; i < n[0]; ++i)
          {
            Point3 p = {{o[0] + i * h, o[1] + j * h, o[2] + k * h}};
            if (perturbation > 0.0)
              for (double &v : p)
                v += u(rng);
            cl.x.push_back(p);
            cl.a.push_back(pt(c * h, c * h, c * h));
          }
    return cl;
  }

  RkParameters
  params(const Support support, const double c)
  {
    RkParameters p;
    p.support  = support;
    p.dilation = c;
    return p;
  }

  Stencil
  stencil_at(const std::vector<Point3> &points, const Cloud &cl, const RkParameters &p)
  {
    const CsrPattern nb = find_support_neighbors(points, cl.x, cl.a, p.support);
    return build_rk_stencil(points, cl.x, cl.a, nb, p);
  }

  /// Candidate pattern listing every particle for every point (the builder must zero the far ones).
  CsrPattern
  all_candidates(const std::size_t n_points, const std::size_t n_particles)
  {
    CsrPattern nb;
    for (std::size_t r = 0; r < n_points; ++r)
      {
        for (std::size_t I = 0; I < n_particles; ++I)
          nb.columns.push_back(static_cast<unsigned int>(I));
        nb.row_offsets.push_back(static_cast<unsigned int>(nb.columns.size()));
      }
    return nb;
  }

  const char *
  name(const Support s)
  {
    return s == Support::box ? "box" : "sphere";
  }

  // Perturbed lattice shared by the reproducing-condition tests: 10^3 particles, h = 2 mm,
  // perturbation up to 0.3 h; evaluation points: 200 random points in [h, 8h]^3 plus the particles
  // whose lattice site lies in [2h, 7h]^3.
  constexpr double       h_pert = 2e-3;
  const Point3           o_pert = {{0.37 * h_pert, -0.21 * h_pert, 0.05 * h_pert}};
  constexpr unsigned int n_pert = 10;

  std::vector<Point3>
  perturbed_eval_points(const Cloud &cl)
  {
    std::mt19937                           rng(42);
    std::uniform_real_distribution<double> u(1.0 * h_pert, 8.0 * h_pert);
    std::vector<Point3>                    pts;
    for (unsigned int t = 0; t < 200; ++t)
      pts.push_back(pt(o_pert[0] + u(rng), o_pert[1] + u(rng), o_pert[2] + u(rng)));
    for (unsigned int k = 2; k <= 7; ++k)
      for (unsigned int j = 2; j <= 7; ++j)
        for (unsigned int i = 2; i <= 7; ++i)
          pts.push_back(cl.x[(k * n_pert + j) * n_pert + i]);
    return pts;
  }
} // namespace


// phi and dphi against the expanded polynomials of formulation.md section 2, continuity of phi,
// phi', phi'' at z = 1/2 and z = 1, and the 1-D normalisation: integral over [-1, 1] = 1/2.
TEST(RkCubicSpline, MatchesClosedForm)
{
  EXPECT_NEAR(phi(0.0), 2.0 / 3.0, 1e-15);
  EXPECT_NEAR(phi(0.5), 1.0 / 6.0, 1e-15);
  EXPECT_NEAR(phi(0.25), 2.0 / 3.0 - 0.25 + 4.0 / 64.0, 1e-15);
  EXPECT_NEAR(phi(0.75), 4.0 / 3.0 / 64.0, 1e-15);
  EXPECT_EQ(phi(1.0), 0.0);
  EXPECT_EQ(phi(1.3), 0.0);
  EXPECT_EQ(dphi(1.3), 0.0);
  EXPECT_NEAR(dphi(0.5), -1.0, 1e-15);
  EXPECT_NEAR(dphi(-0.3), -ref_dphi(0.3), 1e-15);
  EXPECT_NEAR(phi(-0.3), ref_phi(0.3), 1e-15);
  for (double z = 0.0; z <= 1.2; z += 0.01)
    {
      EXPECT_NEAR(phi(z), ref_phi(z), 1e-14) << z;
      EXPECT_NEAR(dphi(z), ref_dphi(z), 1e-14) << z;
      EXPECT_GE(phi(z), 0.0) << z;
      const double d  = 1e-6;
      const double fd = (phi(z + d) - phi(z - d)) / (2 * d);
      if (z > d)
        {
          EXPECT_NEAR(dphi(z), fd, 1e-8) << z;
        }
    }
  // continuity of phi, phi', phi'' (= 4 at 1/2, 0 at 1) from both sides
  const double e = 1e-7;
  EXPECT_NEAR(phi(0.5 - e), phi(0.5 + e), 1e-6);
  EXPECT_NEAR(dphi(0.5 - e), dphi(0.5 + e), 1e-6);
  EXPECT_NEAR((dphi(0.5) - dphi(0.5 - e)) / e, 4.0, 1e-5);
  EXPECT_NEAR((dphi(0.5 + e) - dphi(0.5)) / e, 4.0, 1e-5);
  EXPECT_NEAR(dphi(1.0 - e), 0.0, 1e-12);
  // composite Simpson, exact on each cubic piece (breakpoints on nodes)
  const unsigned int m   = 400;
  double             sum = 0.0;
  for (unsigned int i = 0; i <= m; ++i)
    {
      const double z = -1.0 + 2.0 * i / m;
      const double w = (i == 0 || i == m) ? 1.0 : (i % 2 ? 4.0 : 2.0);
      sum += w * phi(z);
    }
  EXPECT_NEAR(sum * (2.0 / m) / 3.0, 0.5, 1e-14);
}


// 3-D kernel: box = product of 1-D splines with per-direction radii, sphere = spline of |r|/a,
// ellipsoid = spline of |D^{-1} r|; gradients against central differences of the value.
TEST(RkKernel, ValueAndGradientMatchClosedFormAndFiniteDifferences)
{
  std::mt19937                           rng(7);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  const Point3                           a_aniso = {{2e-3, 3e-3, 1.5e-3}};
  const Point3                           a_iso   = {{2e-3, 2e-3, 2e-3}};
  for (const Support s : {Support::box, Support::sphere})
    for (const Point3 &a : {a_aniso, a_iso})
      for (unsigned int t = 0; t < 200; ++t)
        {
          const Point3 r = {{1.1 * a[0] * u(rng), 1.1 * a[1] * u(rng), 1.1 * a[2] * u(rng)}};
          Point3       g;
          const double w = kernel_value_and_gradient(r, a, s, g);
          EXPECT_EQ(w, kernel_value(r, a, s));
          double expected;
          if (s == Support::box)
            expected = ref_kernel(r, a, s);
          else
            {
              const double z = std::sqrt(std::pow(r[0] / a[0], 2) + std::pow(r[1] / a[1], 2) + std::pow(r[2] / a[2], 2));
              expected       = ref_phi(z);
              if (a[0] == a[1] && a[1] == a[2])
                {
                  EXPECT_NEAR(w, ref_kernel(r, a, s), 1e-14);
                }
            }
          EXPECT_NEAR(w, expected, 1e-14);
          for (unsigned int k = 0; k < 3; ++k)
            {
              const double d  = 1e-6 * a[k];
              Point3       rp = r, rm = r;
              rp[k] += d;
              rm[k] -= d;
              const double fd = (kernel_value(rp, a, s) - kernel_value(rm, a, s)) / (2 * d);
              EXPECT_NEAR(g[k], fd, 1e-6 / a[k]) << name(s) << " k=" << k;
            }
        }
  // self: value phi(0)^3 (box) or phi(0) (sphere), zero gradient
  Point3 g;
  EXPECT_NEAR(kernel_value_and_gradient(pt(0, 0, 0), a_aniso, Support::box, g), 8.0 / 27.0, 1e-15);
  EXPECT_EQ(g[0], 0.0);
  EXPECT_NEAR(kernel_value_and_gradient(pt(0, 0, 0), a_aniso, Support::sphere, g), 2.0 / 3.0, 1e-15);
  EXPECT_EQ(g[2], 0.0);
}


// sum Psi = 1 and sum Psi X_I = X (error / h) to 1e-12 on a perturbed lattice (up to 0.3 h, seeded)
// at random points and at particles, box and sphere, dilations 1.5, 2.0, 2.5; no row falls back.
TEST(RkReproducingConditions, PerturbedLattice)
{
  for (const Support s : {Support::box, Support::sphere})
    for (const double c : {1.5, 2.0, 2.5})
      {
        SCOPED_TRACE(std::string(name(s)) + " c=" + std::to_string(c));
        const Cloud               cl  = lattice({n_pert, n_pert, n_pert}, h_pert, o_pert, c, 0.3 * h_pert, 3);
        const std::vector<Point3> pts = perturbed_eval_points(cl);
        const Stencil             st  = stencil_at(pts, cl, params(s, c));
        ASSERT_EQ(st.n_rows(), pts.size());
        double worst0 = 0.0, worst1 = 0.0;
        for (unsigned int r = 0; r < st.n_rows(); ++r)
          {
            EXPECT_EQ(st.fallback[r], 0) << r;
            EXPECT_GT(st.rcond[r], 1e-6) << r;
            double sum = 0.0, sx[3] = {0, 0, 0};
            for (unsigned int e = st.row_offsets[r]; e < st.row_offsets[r + 1]; ++e)
              {
                sum += st.psi[e];
                for (unsigned int k = 0; k < 3; ++k)
                  sx[k] += st.psi[e] * cl.x[st.columns[e]][k];
              }
            worst0 = std::max(worst0, std::abs(sum - 1.0));
            for (unsigned int k = 0; k < 3; ++k)
              worst1 = std::max(worst1, std::abs(sx[k] - pts[r][k]) / h_pert);
          }
        EXPECT_LT(worst0, 1e-12);
        EXPECT_LT(worst1, 1e-12);
      }
}


// sum grad Psi = 0 (times h) and sum X_I (x) grad Psi = I to 1e-12, same sets as above.
TEST(RkGradientConsistency, PerturbedLattice)
{
  for (const Support s : {Support::box, Support::sphere})
    for (const double c : {1.5, 2.0, 2.5})
      {
        SCOPED_TRACE(std::string(name(s)) + " c=" + std::to_string(c));
        const Cloud               cl  = lattice({n_pert, n_pert, n_pert}, h_pert, o_pert, c, 0.3 * h_pert, 3);
        const std::vector<Point3> pts = perturbed_eval_points(cl);
        const Stencil             st  = stencil_at(pts, cl, params(s, c));
        double                    worst0 = 0.0, worst1 = 0.0;
        for (unsigned int r = 0; r < st.n_rows(); ++r)
          {
            double g[3] = {0, 0, 0}, xg[3][3] = {};
            for (unsigned int e = st.row_offsets[r]; e < st.row_offsets[r + 1]; ++e)
              for (unsigned int j = 0; j < 3; ++j)
                {
                  g[j] += st.grad[3 * e + j];
                  for (unsigned int i = 0; i < 3; ++i)
                    xg[i][j] += cl.x[st.columns[e]][i] * st.grad[3 * e + j];
                }
            for (unsigned int i = 0; i < 3; ++i)
              {
                worst0 = std::max(worst0, std::abs(g[i]) * h_pert);
                for (unsigned int j = 0; j < 3; ++j)
                  worst1 = std::max(worst1, std::abs(xg[i][j] - (i == j ? 1.0 : 0.0)));
              }
          }
        EXPECT_LT(worst0, 1e-12);
        EXPECT_LT(worst1, 1e-12);
      }
}


// grad Psi against central differences of Psi (step 1e-5 h) at random points of a perturbed
// lattice; every particle is a candidate so Psi(X +- d e_k) uses the same pattern.
// |fd - grad| <= 1e-6 max_K |grad Psi_K| of the row.
TEST(RkGradient, MatchesFiniteDifferences)
{
  const double h = 1e-3;
  for (const Support s : {Support::box, Support::sphere})
    for (const double c : {1.5, 2.5})
      {
        SCOPED_TRACE(std::string(name(s)) + " c=" + std::to_string(c));
        const Cloud                            cl = lattice({7, 7, 7}, h, pt(0, 0, 0), c, 0.3 * h, 11);
        std::mt19937                           rng(5);
        std::uniform_real_distribution<double> u(1.5 * h, 4.5 * h);
        const double                           d = 1e-5 * h;
        for (unsigned int t = 0; t < 10; ++t)
          {
            const Point3        X = {{u(rng), u(rng), u(rng)}};
            std::vector<Point3> pts(1, X);
            for (unsigned int k = 0; k < 3; ++k)
              {
                Point3 p = X, m = X;
                p[k] += d;
                m[k] -= d;
                pts.push_back(p);
                pts.push_back(m);
              }
            const Stencil st = build_rk_stencil(pts, cl.x, cl.a, all_candidates(pts.size(), cl.x.size()), params(s, c));
            const std::size_t n = cl.x.size();
            double            G = 0.0;
            for (std::size_t I = 0; I < n; ++I)
              for (unsigned int k = 0; k < 3; ++k)
                G = std::max(G, std::abs(st.grad[3 * I + k]));
            ASSERT_GT(G, 0.0);
            for (unsigned int r = 0; r < pts.size(); ++r)
              EXPECT_EQ(st.fallback[r], 0);
            double worst = 0.0;
            for (std::size_t I = 0; I < n; ++I)
              for (unsigned int k = 0; k < 3; ++k)
                {
                  const double fd = (st.psi[(1 + 2 * k) * n + I] - st.psi[(2 + 2 * k) * n + I]) / (2 * d);
                  worst           = std::max(worst, std::abs(fd - st.grad[3 * I + k]));
                }
            EXPECT_LT(worst, 1e-6 * G);
          }
      }
}


namespace
{
  /// Psi_I(X) for all particles, written out independently: unscaled basis H = [1, X - X_I],
  /// M = sum H H^T Phi_I with the kernel of the test and the radii of the neighbour I, M b = e_0 by
  /// Gaussian elimination with partial pivoting, Psi_I = b.H Phi_I.
  std::vector<double>
  dense_psi(const Point3 &X, const std::vector<Point3> &x, const std::vector<Point3> &a, const Support s)
  {
    const auto kernel = [&](const std::size_t I) {
      const Point3 r = pt(X[0] - x[I][0], X[1] - x[I][1], X[2] - x[I][2]);
      if (s == Support::box)
        return ref_kernel(r, a[I], s);
      return ref_phi(std::sqrt(std::pow(r[0] / a[I][0], 2) + std::pow(r[1] / a[I][1], 2) + std::pow(r[2] / a[I][2], 2)));
    };
    double M[4][5] = {};
    for (std::size_t I = 0; I < x.size(); ++I)
      {
        const double H[4] = {1.0, X[0] - x[I][0], X[1] - x[I][1], X[2] - x[I][2]};
        const double w    = kernel(I);
        for (unsigned int p = 0; p < 4; ++p)
          for (unsigned int q = 0; q < 4; ++q)
            M[p][q] += H[p] * H[q] * w;
      }
    M[0][4] = 1.0;
    for (unsigned int c = 0; c < 4; ++c)
      {
        unsigned int piv = c;
        for (unsigned int r = c + 1; r < 4; ++r)
          if (std::abs(M[r][c]) > std::abs(M[piv][c]))
            piv = r;
        for (unsigned int j = 0; j < 5; ++j)
          std::swap(M[c][j], M[piv][j]);
        for (unsigned int r = 0; r < 4; ++r)
          if (r != c)
            {
              const double f = M[r][c] / M[c][c];
              for (unsigned int j = c; j < 5; ++j)
                M[r][j] -= f * M[c][j];
            }
      }
    double b[4];
    for (unsigned int p = 0; p < 4; ++p)
      b[p] = M[p][4] / M[p][p];
    std::vector<double> psi(x.size());
    for (std::size_t I = 0; I < x.size(); ++I)
      psi[I] = (b[0] + b[1] * (X[0] - x[I][0]) + b[2] * (X[1] - x[I][1]) + b[3] * (X[2] - x[I][2])) * kernel(I);
    return psi;
  }
} // namespace


// Psi and grad Psi with particle-dependent, anisotropic radii (a_kI = c_kI h, c_kI random in
// [1.6, 2.6]) against the dense computation above: Psi to 1e-12, grad Psi against its central
// differences (step 1e-5 h) to 1e-6 of the row's largest gradient. Checks that the support
// belongs to the neighbour and that the scaled basis does not change Psi.
TEST(RkShapeFunctions, MatchIndependentDenseComputationWithVariableRadii)
{
  const double                           h = 1e-3;
  std::mt19937                           rng(17);
  std::uniform_real_distribution<double> uc(1.6, 2.6), ux(1.5 * h, 4.5 * h);
  for (const Support s : {Support::box, Support::sphere})
    {
      SCOPED_TRACE(name(s));
      Cloud cl = lattice({7, 7, 7}, h, pt(0.01, 0.02, -0.03), 1.0, 0.3 * h, 19);
      for (Point3 &a : cl.a)
        a = pt(uc(rng) * h, uc(rng) * h, uc(rng) * h);
      for (unsigned int t = 0; t < 10; ++t)
        {
          const Point3        X = pt(0.01 + ux(rng), 0.02 + ux(rng), -0.03 + ux(rng));
          const std::size_t   n = cl.x.size();
          const std::vector<Point3> pts(1, X);
          const Stencil st = build_rk_stencil(pts, cl.x, cl.a, all_candidates(1, n), params(s, 2.0));
          ASSERT_EQ(st.fallback[0], 0);
          const std::vector<double> ref = dense_psi(X, cl.x, cl.a, s);
          double                    G   = 0.0;
          for (std::size_t I = 0; I < n; ++I)
            {
              EXPECT_NEAR(st.psi[I], ref[I], 1e-12) << I;
              for (unsigned int k = 0; k < 3; ++k)
                G = std::max(G, std::abs(st.grad[3 * I + k]));
            }
          const double d = 1e-5 * h;
          for (unsigned int k = 0; k < 3; ++k)
            {
              Point3 p = X, m = X;
              p[k] += d;
              m[k] -= d;
              const std::vector<double> rp = dense_psi(p, cl.x, cl.a, s), rm = dense_psi(m, cl.x, cl.a, s);
              for (std::size_t I = 0; I < n; ++I)
                EXPECT_NEAR(st.grad[3 * I + k], (rp[I] - rm[I]) / (2 * d), 1e-6 * G) << I << " " << k;
            }
        }
    }
}


// Interior particle of a regular lattice (h = 0.25, exact in binary), formulation.md section 2:
// box 1 < c <= 2: 27, 2 < c <= 3: 125; sphere 1 < c <= sqrt2: 7, sqrt2 < c <= sqrt3: 19,
// sqrt3 < c <= 2: 27, 2 < c <= sqrt5: 33. Every entry of the RK row has Psi > 0.
TEST(NeighborCounts, RegularLatticeInteriorParticle)
{
  struct Case
  {
    Support      s;
    double       c;
    unsigned int count;
  };
  const Case cases[] = {{Support::box, 1.01, 27},    {Support::box, 1.5, 27},     {Support::box, 2.0, 27},
                        {Support::box, 2.01, 125},   {Support::box, 2.5, 125},    {Support::box, 3.0, 125},
                        {Support::sphere, 1.2, 7},   {Support::sphere, 1.5, 19},  {Support::sphere, 1.7, 19},
                        {Support::sphere, 1.8, 27},  {Support::sphere, 2.0, 27},  {Support::sphere, 2.2, 33}};
  const double h = 0.25;
  for (const Case &cs : cases)
    {
      SCOPED_TRACE(std::string(name(cs.s)) + " c=" + std::to_string(cs.c));
      const Cloud               cl  = lattice({11, 11, 11}, h, pt(0, 0, 0), cs.c);
      const unsigned int        mid = (5 * 11 + 5) * 11 + 5;
      const std::vector<Point3> pts(1, cl.x[mid]);
      const CsrPattern          nb = find_support_neighbors(pts, cl.x, cl.a, cs.s);
      EXPECT_EQ(nb.row_offsets[1], cs.count);
      EXPECT_TRUE(std::find(nb.columns.begin(), nb.columns.end(), mid) != nb.columns.end()) << "self missing";
      const Stencil st = build_rk_stencil(pts, cl.x, cl.a, nb, params(cs.s, cs.c));
      unsigned int  positive = 0;
      for (const double p : st.psi)
        positive += p > 0.0 ? 1u : 0u;
      EXPECT_EQ(positive, cs.count);
      EXPECT_EQ(st.fallback[0], 0);
    }
}


// formulation.md section 2, 1-D statement: on a regular lattice, a field depending on x only
// (random values per x plane) has RK nodal gradient (u_{i+1} - u_{i-1}) / (2h) at interior
// particles for dilations 1.5 and 2.0 (box and sphere), and zero y, z components.
TEST(RkLatticeGradient, IsCentralDifferenceForDilations15And20)
{
  const double       h = 1e-3;
  const unsigned int n = 7;
  std::mt19937       rng(9);
  std::uniform_real_distribution<double> u01(-1.0, 1.0);
  std::vector<double>                    ux(n);
  for (double &v : ux)
    v = u01(rng);
  for (const Support s : {Support::box, Support::sphere})
    for (const double c : {1.5, 2.0})
      {
        SCOPED_TRACE(std::string(name(s)) + " c=" + std::to_string(c));
        const Cloud cl = lattice({n, n, n}, h, pt(0.1, -0.2, 0.3), c);
        std::vector<Point3>       pts;
        std::vector<unsigned int> ix;
        for (unsigned int k = 1; k + 1 < n; ++k)
          for (unsigned int j = 1; j + 1 < n; ++j)
            for (unsigned int i = 1; i + 1 < n; ++i)
              {
                pts.push_back(cl.x[(k * n + j) * n + i]);
                ix.push_back(i);
              }
        const Stencil st = stencil_at(pts, cl, params(s, c));
        for (unsigned int r = 0; r < st.n_rows(); ++r)
          {
            double g[3] = {0, 0, 0};
            for (unsigned int e = st.row_offsets[r]; e < st.row_offsets[r + 1]; ++e)
              for (unsigned int k = 0; k < 3; ++k)
                g[k] += ux[st.columns[e] % n] * st.grad[3 * e + k];
            const double cd = (ux[ix[r] + 1] - ux[ix[r] - 1]) / (2 * h);
            EXPECT_NEAR(g[0], cd, 1e-12 / h) << r;
            EXPECT_NEAR(g[1], 0.0, 1e-12 / h) << r;
            EXPECT_NEAR(g[2], 0.0, 1e-12 / h) << r;
          }
      }
}


// Counter-check: at dilation 2.5 (box) the planes x +- 2h enter and the gradient is no longer the
// central difference for a generic field.
TEST(RkLatticeGradient, DiffersFromCentralDifferenceForDilation25)
{
  const double        h = 1e-3;
  const unsigned int  n = 9;
  std::vector<double> ux(n);
  for (unsigned int i = 0; i < n; ++i)
    ux[i] = std::pow(static_cast<double>(i), 3); // cubic: stencils with x +- 2h differ
  const Cloud               cl = lattice({n, n, n}, h, pt(0, 0, 0), 2.5);
  const unsigned int        i0 = 4, mid = (4 * n + 4) * n + i0;
  const std::vector<Point3> pts(1, cl.x[mid]);
  const Stencil             st = stencil_at(pts, cl, params(Support::box, 2.5));
  double                    g  = 0.0;
  for (unsigned int e = st.row_offsets[0]; e < st.row_offsets[1]; ++e)
    g += ux[st.columns[e] % n] * st.grad[3 * e];
  const double cd = (ux[i0 + 1] - ux[i0 - 1]) / (2 * h);
  EXPECT_GT(std::abs(g - cd), 1e-3 * std::abs(cd));
}


// A single layer of particles (z = 0): every evaluation point (in the plane or off it) sees coplanar
// neighbours, so M is singular: the row is flagged, rcond < limit, and Psi = Phi / sum Phi (kernel
// written out here), sum Psi = 1, sum grad Psi = 0, grad Psi against central differences.
// Also: fewer than 4 weighted neighbours (3 particles) and an empty row fall back.
TEST(RkIllConditioned, CoplanarNeighboursUseShepardFallback)
{
  const double h = 1e-3;
  for (const Support s : {Support::box, Support::sphere})
    for (const double c : {1.5, 2.5})
      {
        SCOPED_TRACE(std::string(name(s)) + " c=" + std::to_string(c));
        const Cloud                            cl = lattice({7, 7, 1}, h, pt(0, 0, 0), c);
        const RkParameters                     p  = params(s, c);
        std::mt19937                           rng(13);
        std::uniform_real_distribution<double> u(1.5 * h, 4.5 * h), w(-0.4 * h, 0.4 * h);
        for (unsigned int t = 0; t < 20; ++t)
          {
            const Point3        X = {{u(rng), u(rng), t < 10 ? 0.0 : w(rng)}};
            const double        d = 1e-5 * h;
            std::vector<Point3> pts(1, X);
            for (unsigned int k = 0; k < 3; ++k)
              {
                Point3 pp = X, pm = X;
                pp[k] += d;
                pm[k] -= d;
                pts.push_back(pp);
                pts.push_back(pm);
              }
            const std::size_t n  = cl.x.size();
            const Stencil     st = build_rk_stencil(pts, cl.x, cl.a, all_candidates(pts.size(), n), p);
            for (unsigned int r = 0; r < pts.size(); ++r)
              {
                EXPECT_EQ(st.fallback[r], 1) << r;
                EXPECT_LT(st.rcond[r], p.rcond_limit) << r;
              }
            double S = 0.0;
            for (std::size_t I = 0; I < n; ++I)
              S += ref_kernel(pt(X[0] - cl.x[I][0], X[1] - cl.x[I][1], X[2] - cl.x[I][2]), cl.a[I], s);
            double sum = 0.0, g[3] = {0, 0, 0}, G = 0.0;
            for (std::size_t I = 0; I < n; ++I)
              {
                const double shepard =
                  ref_kernel(pt(X[0] - cl.x[I][0], X[1] - cl.x[I][1], X[2] - cl.x[I][2]), cl.a[I], s) / S;
                EXPECT_NEAR(st.psi[I], shepard, 1e-14);
                sum += st.psi[I];
                for (unsigned int k = 0; k < 3; ++k)
                  {
                    g[k] += st.grad[3 * I + k];
                    G = std::max(G, std::abs(st.grad[3 * I + k]));
                  }
              }
            EXPECT_NEAR(sum, 1.0, 1e-14);
            for (unsigned int k = 0; k < 3; ++k)
              EXPECT_LT(std::abs(g[k]) * h, 1e-12);
            for (std::size_t I = 0; I < n; ++I)
              for (unsigned int k = 0; k < 3; ++k)
                {
                  const double fd = (st.psi[(1 + 2 * k) * n + I] - st.psi[(2 + 2 * k) * n + I]) / (2 * d);
                  EXPECT_NEAR(fd, st.grad[3 * I + k], 1e-6 * G) << I << " " << k;
                }
          }
      }

  // Three non-collinear particles: fewer than 4 weighted neighbours.
  {
    const std::vector<Point3> x = {pt(0, 0, 0), pt(1e-3, 0, 0), pt(0, 1e-3, 5e-4)};
    const std::vector<Point3> a(3, pt(2e-3, 2e-3, 2e-3));
    const std::vector<Point3> pts = {pt(3e-4, 3e-4, 1e-4), pt(5e-3, 5e-3, 5e-3)};
    const CsrPattern          nb  = find_support_neighbors(pts, x, a, Support::box);
    ASSERT_EQ(nb.row_offsets[1], 3u);
    ASSERT_EQ(nb.row_offsets[2], 3u); // the far point has no neighbour
    const Stencil st = build_rk_stencil(pts, x, a, nb, RkParameters());
    EXPECT_EQ(st.fallback[0], 1);
    EXPECT_NEAR(st.psi[0] + st.psi[1] + st.psi[2], 1.0, 1e-15);
    EXPECT_NEAR(st.grad[0] + st.grad[3] + st.grad[6], 0.0, 1e-12 / 1e-3);
    EXPECT_EQ(st.fallback[1], 1);
    EXPECT_EQ(st.rcond[1], 0.0);
  }
}


// RkParameters::check() and the builders reject dilation 0.9 with a message naming "dilation";
// 1.0 is accepted; warning() only outside 1.4-1.8.
TEST(RkParameterCheck, RejectsDilationBelowOne)
{
  RkParameters p;
  p.dilation = 0.9;
  try
    {
      p.check();
      FAIL() << "dilation 0.9 accepted";
    }
  catch (const std::invalid_argument &e)
    {
      EXPECT_NE(std::string(e.what()).find("dilation"), std::string::npos) << e.what();
    }
  const std::vector<Point3> x(1, pt(0, 0, 0)), a(1, pt(1, 1, 1));
  CsrPattern                nb;
  nb.columns     = {0};
  nb.row_offsets = {0, 1};
  EXPECT_THROW(build_rk_stencil(x, x, a, nb, p), std::invalid_argument);
  EXPECT_THROW(support_radii_from_spacing(a, p), std::invalid_argument);

  p.dilation = 1.0;
  EXPECT_NO_THROW(p.check());
  EXPECT_FALSE(p.warning().empty());
  p.dilation = 1.5;
  EXPECT_TRUE(p.warning().empty());
  EXPECT_NEAR(support_radii_from_spacing({pt(1e-3, 2e-3, 4e-3)}, p)[0][2], 6e-3, 1e-18);
  p.rcond_limit = -1.0;
  EXPECT_THROW(p.check(), std::invalid_argument);
}


// The transposed index lists every stencil entry exactly once, each under its own column with the
// right row, rows ascending; a scatter written as a gather over it equals the direct scatter.
TEST(RkTransposedIndex, ListsEveryEntryOnce)
{
  const Cloud               cl  = lattice({8, 8, 8}, 1e-3, pt(0, 0, 0), 1.5, 0.3e-3, 21);
  std::vector<Point3>       pts = cl.x;
  std::mt19937              rng(3);
  std::uniform_real_distribution<double> u(-1e-3, 8e-3);
  for (unsigned int t = 0; t < 300; ++t)
    pts.push_back(pt(u(rng), u(rng), u(rng))); // some outside: short or empty rows
  const Stencil         st = stencil_at(pts, cl, params(Support::box, 1.5));
  const TransposedIndex tr = build_transposed_index(st);

  ASSERT_EQ(tr.column_offsets.size(), cl.x.size() + 1);
  ASSERT_EQ(tr.column_offsets.back(), st.n_entries());
  ASSERT_EQ(tr.rows.size(), st.n_entries());
  ASSERT_EQ(tr.entries.size(), st.n_entries());
  std::vector<unsigned int> seen(st.n_entries(), 0);
  for (unsigned int K = 0; K < cl.x.size(); ++K)
    for (unsigned int t = tr.column_offsets[K]; t < tr.column_offsets[K + 1]; ++t)
      {
        const unsigned int e = tr.entries[t];
        const unsigned int r = tr.rows[t];
        ASSERT_LT(e, st.n_entries());
        ++seen[e];
        EXPECT_EQ(st.columns[e], K);
        EXPECT_GE(e, st.row_offsets[r]);
        EXPECT_LT(e, st.row_offsets[r + 1]);
        if (t > tr.column_offsets[K])
          {
            EXPECT_LT(tr.rows[t - 1], r);
          }
      }
  for (const unsigned int v : seen)
    ASSERT_EQ(v, 1u);

  std::vector<double> g(st.n_rows());
  for (double &v : g)
    v = u(rng);
  std::vector<double> direct(cl.x.size(), 0.0), gathered(cl.x.size(), 0.0);
  for (unsigned int r = 0; r < st.n_rows(); ++r)
    for (unsigned int e = st.row_offsets[r]; e < st.row_offsets[r + 1]; ++e)
      direct[st.columns[e]] += st.psi[e] * g[r];
  for (unsigned int K = 0; K < cl.x.size(); ++K)
    for (unsigned int t = tr.column_offsets[K]; t < tr.column_offsets[K + 1]; ++t)
      gathered[K] += st.psi[tr.entries[t]] * g[tr.rows[t]];
  for (unsigned int K = 0; K < cl.x.size(); ++K)
    EXPECT_NEAR(gathered[K], direct[K], 1e-15 + 1e-13 * std::abs(direct[K]));
}


namespace
{
  /// O(N^2) search written out: box |r_k| < a_k for all k; sphere (equal radii) |r| < a;
  /// ellipsoid sum (r_k / a_k)^2 < 1.
  std::vector<std::vector<unsigned int>>
  brute_force(const std::vector<Point3> &pts, const Cloud &cl, const Support s, const bool isotropic)
  {
    std::vector<std::vector<unsigned int>> rows(pts.size());
    for (std::size_t r = 0; r < pts.size(); ++r)
      for (std::size_t I = 0; I < cl.x.size(); ++I)
        {
          const double dx = pts[r][0] - cl.x[I][0], dy = pts[r][1] - cl.x[I][1], dz = pts[r][2] - cl.x[I][2];
          const Point3 &a = cl.a[I];
          bool          in;
          if (s == Support::box)
            in = std::abs(dx) < a[0] && std::abs(dy) < a[1] && std::abs(dz) < a[2];
          else if (isotropic)
            in = std::sqrt(dx * dx + dy * dy + dz * dz) < a[0];
          else
            in = (dx / a[0]) * (dx / a[0]) + (dy / a[1]) * (dy / a[1]) + (dz / a[2]) * (dz / a[2]) < 1.0;
          if (in)
            rows[r].push_back(static_cast<unsigned int>(I));
        }
    return rows;
  }

  void
  expect_same_rows(const CsrPattern &nb, const std::vector<std::vector<unsigned int>> &ref)
  {
    ASSERT_EQ(nb.n_rows(), ref.size());
    std::size_t total = 0;
    for (std::size_t r = 0; r < ref.size(); ++r)
      {
        const std::vector<unsigned int> got(nb.columns.begin() + nb.row_offsets[r],
                                            nb.columns.begin() + nb.row_offsets[r + 1]);
        EXPECT_EQ(got, ref[r]) << "row " << r;
        total += ref[r].size();
      }
    EXPECT_EQ(nb.columns.size(), total);
  }
} // namespace


// Binned search against the O(N^2) search above: 2000 random particles with random radii
// (box: per direction; sphere: equal and unequal radii), evaluation points = the particles (self
// included) plus 500 random points, some outside the particles' bounding box.
TEST(NeighborBinning, MatchesBruteForce)
{
  std::mt19937                           rng(2024);
  std::uniform_real_distribution<double> ux(0.0, 1.0), uy(0.0, 0.5), uz(0.0, 2.0), ua(0.02, 0.12),
    uo(-0.2, 2.2);
  for (const Support s : {Support::box, Support::sphere})
    for (const bool isotropic : {true, false})
      {
        SCOPED_TRACE(std::string(name(s)) + (isotropic ? " isotropic" : " anisotropic"));
        Cloud cl;
        for (unsigned int i = 0; i < 2000; ++i)
          {
            cl.x.push_back(pt(ux(rng), uy(rng), uz(rng)));
            if (isotropic)
              {
                const double a = ua(rng);
                cl.a.push_back(pt(a, a, a));
              }
            else
              cl.a.push_back(pt(ua(rng), ua(rng), ua(rng)));
          }
        std::vector<Point3> pts = cl.x;
        for (unsigned int t = 0; t < 500; ++t)
          pts.push_back(pt(0.5 * uo(rng), 0.25 * uo(rng), uo(rng)));
        const CsrPattern nb = find_support_neighbors(pts, cl.x, cl.a, s);
        expect_same_rows(nb, brute_force(pts, cl, s, isotropic));
        for (unsigned int i = 0; i < 2000; ++i)
          EXPECT_TRUE(std::binary_search(nb.columns.begin() + nb.row_offsets[i],
                                         nb.columns.begin() + nb.row_offsets[i + 1], i))
            << "self missing " << i;
      }
}


// Two far-apart clusters with small radii: the bins are enlarged to bound their number, the result
// stays exact.
TEST(NeighborBinning, SparseClustersMatchBruteForce)
{
  std::mt19937                           rng(77);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  Cloud                                  cl;
  for (unsigned int i = 0; i < 400; ++i)
    {
      const double off = i % 2 ? 1000.0 : 0.0;
      cl.x.push_back(pt(off + u(rng), u(rng), off + u(rng)));
      cl.a.push_back(pt(0.05 + 0.1 * u(rng), 0.05 + 0.1 * u(rng), 0.05 + 0.1 * u(rng)));
    }
  std::vector<Point3> pts = cl.x;
  for (unsigned int t = 0; t < 200; ++t)
    pts.push_back(pt(1000.0 * u(rng), u(rng), 1000.0 * u(rng)));
  expect_same_rows(find_support_neighbors(pts, cl.x, cl.a, Support::box), brute_force(pts, cl, Support::box, false));
}


// A graded cloud: 3000 small supports beside 30 ten times larger ones (a far field converted
// next to a fine core). The bins follow the small radii; the large supports span many bins and
// must still be found from every point inside them.
TEST(NeighborBinning, GradedRadiiMatchBruteForce)
{
  std::mt19937                           rng(11);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  for (const Support s : {Support::box, Support::sphere})
    {
      SCOPED_TRACE(name(s));
      Cloud cl;
      for (unsigned int i = 0; i < 3030; ++i)
        {
          cl.x.push_back(pt(u(rng), u(rng), 0.5 * u(rng)));
          const double a = i % 101 == 0 ? 0.3 + 0.1 * u(rng) : 0.03 + 0.01 * u(rng);
          cl.a.push_back(pt(a, a, a));
        }
      std::vector<Point3> pts = cl.x;
      for (unsigned int t = 0; t < 500; ++t)
        pts.push_back(pt(1.4 * u(rng) - 0.2, 1.4 * u(rng) - 0.2, u(rng) - 0.25));
      expect_same_rows(find_support_neighbors(pts, cl.x, cl.a, s), brute_force(pts, cl, s, true));
    }
}
