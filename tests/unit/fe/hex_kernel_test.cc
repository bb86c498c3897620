// SPDX-License-Identifier: LGPL-2.1-or-later
// Unit tests of the uniform-strain hexahedron kernels (include/shard/fe/hex_kernel.h) against
// closed forms and computations written out here (doc/manual/fe.md, "Tests"). Node order is
// deal.II's lexicographic order: node a at reference corner ((a & 1), (a >> 1) & 1, (a >> 2) & 1).
#include <shard/base/tensor.h>
#include <shard/fe/hex_kernel.h>

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <random>

namespace
{
  using namespace shard::fe;
  using namespace shard::tensor;

  using Mat = double[3][3];

  struct Hex
  {
    double x[8][3];
  };

  /// Reference corner coordinate k (0 or 1) of node a.
  int
  corner(const unsigned int a, const unsigned int k)
  {
    return static_cast<int>((a >> k) & 1u);
  }

  /// The cube [0,1]^3 mapped by x = A xi + t.
  Hex
  affine_cube(const Mat &A, const double (&t)[3])
  {
    Hex h;
    for (unsigned int a = 0; a < 8; ++a)
      for (unsigned int i = 0; i < 3; ++i)
        h.x[a][i] = t[i] + A[i][0] * corner(a, 0) + A[i][1] * corner(a, 1) + A[i][2] * corner(a, 2);
    return h;
  }

  Hex
  box(const double a, const double b, const double c)
  {
    const Mat    A    = {{a, 0, 0}, {0, b, 0}, {0, 0, c}};
    const double t[3] = {0, 0, 0};
    return affine_cube(A, t);
  }

  double
  det3(const Mat &A)
  {
    return A[0][0] * (A[1][1] * A[2][2] - A[1][2] * A[2][1]) - A[0][1] * (A[1][0] * A[2][2] - A[1][2] * A[2][0]) +
           A[0][2] * (A[1][0] * A[2][1] - A[1][1] * A[2][0]);
  }

  /// Rodrigues' formula: rotation by |w| t about w, i.e. exp(t [w]_x).
  void
  rodrigues(const double (&w)[3], const double t, Mat &R)
  {
    const double theta = t * std::sqrt(w[0] * w[0] + w[1] * w[1] + w[2] * w[2]);
    double       n[3]  = {0, 0, 0};
    if (theta > 0)
      for (unsigned int i = 0; i < 3; ++i)
        n[i] = t * w[i] / theta;
    const Mat K = {{0, -n[2], n[1]}, {n[2], 0, -n[0]}, {-n[1], n[0], 0}};
    for (unsigned int i = 0; i < 3; ++i)
      for (unsigned int j = 0; j < 3; ++j)
        {
          double KK = 0;
          for (unsigned int k = 0; k < 3; ++k)
            KK += K[i][k] * K[k][j];
          R[i][j] = (i == j ? 1. : 0.) + std::sin(theta) * K[i][j] + (1. - std::cos(theta)) * KK;
        }
  }

  /// Skew tensor [w]_x with [w]_x v = w x v.
  void
  skew(const double (&w)[3], Mat &W)
  {
    const Mat S = {{0, -w[2], w[1]}, {w[2], 0, -w[0]}, {-w[1], w[0], 0}};
    std::copy(&S[0][0], &S[0][0] + 9, &W[0][0]);
  }

  /// Random rotation from a random axis and angle.
  void
  random_rotation(std::mt19937 &rng, Mat &R)
  {
    std::normal_distribution<double>       n(0., 1.);
    std::uniform_real_distribution<double> angle(-3., 3.);
    double                                 w[3] = {n(rng), n(rng), n(rng)};
    const double norm = std::sqrt(w[0] * w[0] + w[1] * w[1] + w[2] * w[2]);
    for (double &c : w)
      c /= norm;
    rodrigues(w, angle(rng), R);
  }

  /// Unit cube with every coordinate perturbed by up to @p amplitude, then rotated, stretched
  /// and translated: a distorted (non-parallelepiped) hexahedron with warped faces.
  Hex
  perturbed_hex(std::mt19937 &rng, const double amplitude = 0.2)
  {
    std::uniform_real_distribution<double> u(-1., 1.), s(0.5, 2.);
    Mat                                    R;
    random_rotation(rng, R);
    const double scale[3] = {s(rng), s(rng), s(rng)};
    const double t[3]     = {u(rng), u(rng), u(rng)};
    Hex          h;
    for (unsigned int a = 0; a < 8; ++a)
      {
        double p[3];
        for (unsigned int k = 0; k < 3; ++k)
          p[k] = scale[k] * (corner(a, k) + amplitude * u(rng));
        for (unsigned int i = 0; i < 3; ++i)
          h.x[a][i] = t[i] + R[i][0] * p[0] + R[i][1] * p[1] + R[i][2] * p[2];
      }
    return h;
  }

  /// Shape function gradients with respect to xi in [0,1]^3 at @p xi.
  void
  shape_gradients(const double (&xi)[3], double (&dN)[8][3])
  {
    for (unsigned int a = 0; a < 8; ++a)
      {
        double f[3], df[3];
        for (unsigned int k = 0; k < 3; ++k)
          {
            f[k]  = corner(a, k) ? xi[k] : 1. - xi[k];
            df[k] = corner(a, k) ? 1. : -1.;
          }
        dN[a][0] = df[0] * f[1] * f[2];
        dN[a][1] = f[0] * df[1] * f[2];
        dN[a][2] = f[0] * f[1] * df[2];
      }
  }

  /// Independent volume and volume gradient by 2x2x2 Gauss quadrature:
  /// V = int det J, B_a = int grad N_a dV = int cof(J) grad_xi N_a. Both integrands have degree
  /// <= 2 in each reference coordinate for a trilinear map, so the rule is exact.
  double
  quadrature(const Hex &h, double (&B)[8][3])
  {
    const double g[2]   = {0.5 - 0.5 / std::sqrt(3.), 0.5 + 0.5 / std::sqrt(3.)};
    double       volume = 0;
    for (auto &row : B)
      for (double &c : row)
        c = 0;
    for (unsigned int q = 0; q < 8; ++q)
      {
        const double xi[3] = {g[q & 1], g[(q >> 1) & 1], g[(q >> 2) & 1]};
        double       dN[8][3];
        shape_gradients(xi, dN);
        Mat J = {};
        for (unsigned int a = 0; a < 8; ++a)
          for (unsigned int i = 0; i < 3; ++i)
            for (unsigned int j = 0; j < 3; ++j)
              J[i][j] += h.x[a][i] * dN[a][j];
        // Cofactor matrix C = det(J) J^{-T}.
        Mat C;
        for (unsigned int i = 0; i < 3; ++i)
          for (unsigned int j = 0; j < 3; ++j)
            {
              const unsigned int i1 = (i + 1) % 3, i2 = (i + 2) % 3, j1 = (j + 1) % 3, j2 = (j + 2) % 3;
              C[i][j] = J[i1][j1] * J[i2][j2] - J[i1][j2] * J[i2][j1];
            }
        const double w = 1. / 8.;
        volume += w * det3(J);
        for (unsigned int a = 0; a < 8; ++a)
          for (unsigned int i = 0; i < 3; ++i)
            B[a][i] += w * (C[i][0] * dN[a][0] + C[i][1] * dN[a][1] + C[i][2] * dN[a][2]);
      }
    return volume;
  }

  double
  quadrature_volume(const Hex &h)
  {
    double B[8][3];
    return quadrature(h, B);
  }

  double
  max_abs(const double (&B)[8][3])
  {
    double m = 0;
    for (const auto &row : B)
      for (const double c : row)
        m = std::max(m, std::abs(c));
    return m;
  }

  /// Flanagan-Belytschko base vectors written from their definition: xi eta, eta zeta, xi zeta,
  /// xi eta zeta at the nodes, with the reference coordinates in {-1, 1}.
  double
  hourglass_base(const unsigned int mode, const unsigned int a)
  {
    const double s[3] = {2. * corner(a, 0) - 1., 2. * corner(a, 1) - 1., 2. * corner(a, 2) - 1.};
    switch (mode)
      {
        case 0:
          return s[0] * s[1];
        case 1:
          return s[1] * s[2];
        case 2:
          return s[0] * s[2];
        default:
          return s[0] * s[1] * s[2];
      }
  }

  /// Frobenius norm of A - B.
  double
  distance(const Mat &A, const Mat &B)
  {
    double d = 0;
    for (unsigned int i = 0; i < 3; ++i)
      for (unsigned int j = 0; j < 3; ++j)
        d += (A[i][j] - B[i][j]) * (A[i][j] - B[i][j]);
    return std::sqrt(d);
  }

  void
  multiply(const Mat &A, const Mat &B, Mat &C)
  {
    for (unsigned int i = 0; i < 3; ++i)
      for (unsigned int j = 0; j < 3; ++j)
        {
          C[i][j] = 0;
          for (unsigned int k = 0; k < 3; ++k)
            C[i][j] += A[i][k] * B[k][j];
        }
  }

  /// Symmetric tensor from 6-component storage xx, yy, zz, yz, xz, xy.
  void
  unpack(const double *s, Mat &S)
  {
    const Mat T = {{s[0], s[5], s[4]}, {s[5], s[1], s[3]}, {s[4], s[3], s[2]}};
    std::copy(&T[0][0], &T[0][0] + 9, &S[0][0]);
  }

  double
  von_mises(const Mat &S)
  {
    const double p = (S[0][0] + S[1][1] + S[2][2]) / 3.;
    double       ss = 0;
    for (unsigned int i = 0; i < 3; ++i)
      for (unsigned int j = 0; j < 3; ++j)
        {
          const double d = S[i][j] - (i == j ? p : 0.);
          ss += d * d;
        }
    return std::sqrt(1.5 * ss);
  }
} // namespace

// --- 1. Volume ----------------------------------------------------------------------------

TEST(HexKernelTest, VolumeOfUnitCubeAndBox)
{
  double B[8][3];
  EXPECT_NEAR(hex_volume_gradient(box(1, 1, 1).x, B), 1., 1e-15);
  EXPECT_NEAR(hex_volume_gradient(box(2., 3., 0.5).x, B), 3., 3e-15);
  EXPECT_NEAR(hex_volume_gradient(box(1e-3, 2e-3, 5e-4).x, B), 1e-9, 1e-24);
}

// An affine image of the unit cube (shear, stretch, rotation, translation) has volume det A;
// a mirrored one is reported with negative volume det A < 0.
TEST(HexKernelTest, VolumeOfAffineCubeIsDetA)
{
  std::mt19937                           rng(11);
  std::uniform_real_distribution<double> u(-1., 1.);
  for (int trial = 0; trial < 20; ++trial)
    {
      Mat A;
      for (auto &row : A)
        for (double &c : row)
          c = u(rng);
      for (unsigned int i = 0; i < 3; ++i)
        A[i][i] += 2.;
      const double t[3] = {10 * u(rng), 10 * u(rng), 10 * u(rng)};
      double       B[8][3];
      const double detA = det3(A);
      ASSERT_GT(detA, 0.);
      EXPECT_NEAR(hex_volume_gradient(affine_cube(A, t).x, B), detA, 1e-13 * detA);
      // Mirror x -> -x (the node order is kept, so the element is inverted).
      for (unsigned int j = 0; j < 3; ++j)
        A[0][j] = -A[0][j];
      EXPECT_NEAR(hex_volume_gradient(affine_cube(A, t).x, B), -detA, 1e-13 * detA);
    }
}

// Frustum of a square pyramid (bottom 2x2, top 1x1, height 4; a trilinear image of the cube with
// trapezoidal side faces): V = h/3 (A1 + A2 + sqrt(A1 A2)) = 28/3.
TEST(HexKernelTest, VolumeOfFrustum)
{
  Hex h;
  for (unsigned int a = 0; a < 8; ++a)
    {
      const double half = corner(a, 2) ? 0.5 : 1.;
      h.x[a][0]         = corner(a, 0) ? half : -half;
      h.x[a][1]         = corner(a, 1) ? half : -half;
      h.x[a][2]         = 4. * corner(a, 2);
    }
  double B[8][3];
  EXPECT_NEAR(hex_volume_gradient(h.x, B), 28. / 3., 1e-14 * 28. / 3.);
  EXPECT_NEAR(quadrature_volume(h), 28. / 3., 1e-14 * 28. / 3.);
}

// Randomly perturbed hexahedra against 2x2x2 Gauss quadrature of det J.
TEST(HexKernelTest, VolumeOfPerturbedHexMatchesQuadrature)
{
  std::mt19937 rng(2024);
  for (int trial = 0; trial < 200; ++trial)
    {
      const Hex    h = perturbed_hex(rng);
      double       B[8][3];
      const double V = hex_volume_gradient(h.x, B);
      const double Vq = quadrature_volume(h);
      ASSERT_GT(Vq, 0.);
      EXPECT_NEAR(V, Vq, 1e-13 * Vq) << "trial " << trial;
    }
}

// --- 2. Volume gradient -------------------------------------------------------------------

// B_a = dV/dx_a: central differences of the independent quadrature volume and of the returned
// volume (V is linear in each single coordinate, so the difference quotient is exact up to
// round-off), and B_a = int grad N_a dV by Gauss quadrature.
TEST(HexKernelTest, VolumeGradientMatchesFiniteDifferences)
{
  std::mt19937 rng(7);
  for (int trial = 0; trial < 50; ++trial)
    {
      const Hex h = perturbed_hex(rng, 0.25);
      double    B[8][3], Bq[8][3], scratch[8][3];
      hex_volume_gradient(h.x, B);
      quadrature(h, Bq);
      const double scale = max_abs(B);
      const double step  = 1e-5;
      for (unsigned int a = 0; a < 8; ++a)
        for (unsigned int i = 0; i < 3; ++i)
          {
            Hex plus = h, minus = h;
            plus.x[a][i] += step;
            minus.x[a][i] -= step;
            const double fd_independent = (quadrature_volume(plus) - quadrature_volume(minus)) / (2 * step);
            const double fd_code =
              (hex_volume_gradient(plus.x, scratch) - hex_volume_gradient(minus.x, scratch)) / (2 * step);
            EXPECT_NEAR(B[a][i], fd_independent, 1e-7 * scale) << "trial " << trial << " node " << a << " dir " << i;
            EXPECT_NEAR(B[a][i], fd_code, 1e-7 * scale) << "trial " << trial << " node " << a << " dir " << i;
            EXPECT_NEAR(B[a][i], Bq[a][i], 1e-13 * scale) << "trial " << trial << " node " << a << " dir " << i;
          }
    }
}

// Unit cube: B_a = int grad N_a = (1/4)(2 xi_a - 1, 2 eta_a - 1, 2 zeta_a - 1).
TEST(HexKernelTest, VolumeGradientOfUnitCube)
{
  double B[8][3];
  hex_volume_gradient(box(1, 1, 1).x, B);
  for (unsigned int a = 0; a < 8; ++a)
    for (unsigned int k = 0; k < 3; ++k)
      EXPECT_NEAR(B[a][k], 0.25 * (2. * corner(a, k) - 1.), 1e-16) << "node " << a;
}

// A millimetre element 10 m from the origin: the gradient equals that of the same element at the
// origin (the kernel works relative to node 0 to keep the cross products well conditioned).
TEST(HexKernelTest, VolumeGradientOfSmallDistantElement)
{
  std::mt19937 rng(99);
  for (int trial = 0; trial < 20; ++trial)
    {
      Hex h = perturbed_hex(rng);
      for (auto &p : h.x)
        for (double &c : p)
          c *= 1e-3;
      Hex far = h;
      for (auto &p : far.x)
        {
          p[0] += 10.;
          p[1] -= 7.;
          p[2] += 3.;
        }
      double       B[8][3], Bf[8][3];
      const double V  = hex_volume_gradient(h.x, B);
      const double Vf = hex_volume_gradient(far.x, Bf);
      EXPECT_NEAR(Vf, V, 1e-9 * V);
      const double scale = max_abs(B);
      for (unsigned int a = 0; a < 8; ++a)
        for (unsigned int i = 0; i < 3; ++i)
          EXPECT_NEAR(Bf[a][i], B[a][i], 1e-9 * scale);
    }
}

// --- 3. Translation invariance and the uniform-strain patch test ---------------------------

// sum_a B_a = 0 and sum_a x_a (x) B_a = V I; so for v = G x + c the mean velocity gradient
// L = V^-1 sum_a v_a (x) B_a equals G exactly on distorted hexahedra.
TEST(HexKernelTest, PatchTestLinearFieldsAreExact)
{
  std::mt19937                           rng(31);
  std::uniform_real_distribution<double> u(-1., 1.);
  for (int trial = 0; trial < 100; ++trial)
    {
      const Hex    h = perturbed_hex(rng, 0.25);
      double       B[8][3];
      const double V     = hex_volume_gradient(h.x, B);
      const double scale = max_abs(B);
      for (unsigned int i = 0; i < 3; ++i)
        {
          double sum = 0;
          for (unsigned int a = 0; a < 8; ++a)
            sum += B[a][i];
          EXPECT_NEAR(sum, 0., 1e-14 * scale);
        }
      for (unsigned int i = 0; i < 3; ++i)
        for (unsigned int j = 0; j < 3; ++j)
          {
            double xB = 0;
            for (unsigned int a = 0; a < 8; ++a)
              xB += h.x[a][i] * B[a][j];
            EXPECT_NEAR(xB / V, i == j ? 1. : 0., 1e-12) << "trial " << trial;
          }
      Mat    G;
      double c[3], gnorm = 0;
      for (unsigned int i = 0; i < 3; ++i)
        {
          c[i] = u(rng);
          for (unsigned int j = 0; j < 3; ++j)
            {
              G[i][j] = u(rng);
              gnorm   = std::max(gnorm, std::abs(G[i][j]));
            }
        }
      double v[8][3];
      for (unsigned int a = 0; a < 8; ++a)
        for (unsigned int i = 0; i < 3; ++i)
          v[a][i] = c[i] + G[i][0] * h.x[a][0] + G[i][1] * h.x[a][1] + G[i][2] * h.x[a][2];
      for (unsigned int i = 0; i < 3; ++i)
        for (unsigned int j = 0; j < 3; ++j)
          {
            double L = 0;
            for (unsigned int a = 0; a < 8; ++a)
              L += v[a][i] * B[a][j];
            EXPECT_NEAR(L / V, G[i][j], 1e-12 * gnorm) << "trial " << trial;
          }
    }
}

// --- 4. Internal force equilibrium ---------------------------------------------------------

// For symmetric sigma and f_a = -sigma B_a: sum_a f_a = 0 and sum_a x_a x f_a = 0.
TEST(HexKernelTest, InternalForcesAreInEquilibrium)
{
  std::mt19937                           rng(5);
  std::uniform_real_distribution<double> u(-1., 1.);
  for (int trial = 0; trial < 100; ++trial)
    {
      const Hex h = perturbed_hex(rng, 0.25);
      double    B[8][3];
      hex_volume_gradient(h.x, B);
      const double s[6] = {u(rng), u(rng), u(rng), u(rng), u(rng), u(rng)};
      Mat          sigma;
      unpack(s, sigma);
      double f[8][3];
      double force_scale = 0, moment_scale = 0;
      for (unsigned int a = 0; a < 8; ++a)
        {
          for (unsigned int i = 0; i < 3; ++i)
            f[a][i] = -(sigma[i][0] * B[a][0] + sigma[i][1] * B[a][1] + sigma[i][2] * B[a][2]);
          const double fa = std::sqrt(f[a][0] * f[a][0] + f[a][1] * f[a][1] + f[a][2] * f[a][2]);
          const double xa = std::sqrt(h.x[a][0] * h.x[a][0] + h.x[a][1] * h.x[a][1] + h.x[a][2] * h.x[a][2]);
          force_scale += fa;
          moment_scale += fa * xa;
        }
      double F[3] = {0, 0, 0}, M[3] = {0, 0, 0};
      for (unsigned int a = 0; a < 8; ++a)
        for (unsigned int i = 0; i < 3; ++i)
          {
            const unsigned int j = (i + 1) % 3, k = (i + 2) % 3;
            F[i] += f[a][i];
            M[i] += h.x[a][j] * f[a][k] - h.x[a][k] * f[a][j];
          }
      for (unsigned int i = 0; i < 3; ++i)
        {
          EXPECT_NEAR(F[i], 0., 1e-14 * force_scale) << "trial " << trial;
          EXPECT_NEAR(M[i], 0., 1e-13 * moment_scale) << "trial " << trial;
        }
    }
}

// --- 5. Hourglass vectors ------------------------------------------------------------------

// gamma_alpha is orthogonal to every linear field: sum_a gamma_alpha,a (c + G x_a) = 0, i.e.
// sum_a gamma_alpha,a = 0 and sum_a gamma_alpha,a x_a = 0. Together with gamma_alpha - Gamma_alpha
// lying in the span of the columns of B (checked by least squares) this characterises gamma.
TEST(HexKernelTest, HourglassVectorsAreOrthogonalToLinearFields)
{
  std::mt19937 rng(17);
  for (int trial = 0; trial < 100; ++trial)
    {
      const Hex    h = perturbed_hex(rng, 0.25);
      double       B[8][3], gamma[4][8];
      const double V = hex_volume_gradient(h.x, B);
      hex_hourglass_vectors(h.x, B, V, gamma);
      double xscale = 0;
      for (const auto &p : h.x)
        for (const double c : p)
          xscale = std::max(xscale, std::abs(c));
      for (unsigned int m = 0; m < 4; ++m)
        {
          double sum = 0, gscale = 0;
          for (unsigned int a = 0; a < 8; ++a)
            {
              sum += gamma[m][a];
              gscale = std::max(gscale, std::abs(gamma[m][a]));
            }
          EXPECT_NEAR(sum, 0., 1e-12 * gscale) << "trial " << trial << " mode " << m;
          for (unsigned int i = 0; i < 3; ++i)
            {
              double gx = 0;
              for (unsigned int a = 0; a < 8; ++a)
                gx += gamma[m][a] * h.x[a][i];
              EXPECT_NEAR(gx, 0., 1e-12 * gscale * xscale) << "trial " << trial << " mode " << m;
            }
          // d = gamma - Gamma should be B c for some c: solve (B^T B) c = B^T d, check the residual.
          double d[8];
          for (unsigned int a = 0; a < 8; ++a)
            d[a] = gamma[m][a] - hourglass_base(m, a);
          Mat    N = {};
          double r[3] = {0, 0, 0};
          for (unsigned int a = 0; a < 8; ++a)
            for (unsigned int i = 0; i < 3; ++i)
              {
                r[i] += B[a][i] * d[a];
                for (unsigned int j = 0; j < 3; ++j)
                  N[i][j] += B[a][i] * B[a][j];
              }
          const double detN = det3(N);
          double       c[3];
          for (unsigned int k = 0; k < 3; ++k)
            {
              Mat Nk;
              std::copy(&N[0][0], &N[0][0] + 9, &Nk[0][0]);
              for (unsigned int i = 0; i < 3; ++i)
                Nk[i][k] = r[i];
              c[k] = det3(Nk) / detN; // Cramer's rule
            }
          for (unsigned int a = 0; a < 8; ++a)
            EXPECT_NEAR(d[a], B[a][0] * c[0] + B[a][1] * c[1] + B[a][2] * c[2], 1e-11)
              << "trial " << trial << " mode " << m;
        }
    }
}

// On the unit cube and on any parallelepiped the base vectors are already orthogonal to the
// linear fields, so gamma = Gamma.
TEST(HexKernelTest, HourglassVectorsOfCubeAreBaseVectors)
{
  std::mt19937                           rng(3);
  std::uniform_real_distribution<double> u(-0.5, 0.5);
  for (int trial = 0; trial < 10; ++trial)
    {
      Mat A = {{1, 0, 0}, {0, 1, 0}, {0, 0, 1}};
      if (trial > 0)
        for (auto &row : A)
          for (double &c : row)
            c += u(rng);
      const double t[3] = {trial > 0 ? 4 * u(rng) : 0., trial > 0 ? 4 * u(rng) : 0., 0.};
      const Hex    h    = affine_cube(A, t);
      double       B[8][3], gamma[4][8];
      const double V = hex_volume_gradient(h.x, B);
      ASSERT_GT(V, 0.);
      hex_hourglass_vectors(h.x, B, V, gamma);
      for (unsigned int m = 0; m < 4; ++m)
        for (unsigned int a = 0; a < 8; ++a)
          EXPECT_NEAR(gamma[m][a], hourglass_base(m, a), 1e-13) << "trial " << trial << " mode " << m;
    }
}

// --- 6. Max face area ----------------------------------------------------------------------

TEST(HexKernelTest, MaxFaceAreaOfBoxes)
{
  EXPECT_NEAR(hex_max_face_area(box(1, 1, 1).x), 1., 1e-15);
  std::mt19937 rng(8);
  // Each of the three face pairs in turn is the largest one.
  const double dims[3][3] = {{2., 3., 0.5}, {0.5, 2., 3.}, {3., 0.5, 2.}};
  for (const auto &d : dims)
    {
      const double expected = std::max({d[0] * d[1], d[1] * d[2], d[2] * d[0]});
      EXPECT_NEAR(hex_max_face_area(box(d[0], d[1], d[2]).x), expected, 1e-14 * expected);
      // The same box rotated and translated.
      Mat R;
      random_rotation(rng, R);
      for (unsigned int i = 0; i < 3; ++i)
        for (unsigned int j = 0; j < 3; ++j)
          R[i][j] *= d[j];
      const double t[3] = {1.5, -2., 0.25};
      EXPECT_NEAR(hex_max_face_area(affine_cube(R, t).x), expected, 1e-14 * expected);
    }
}

// Frustum (bottom 2x2, top 1x1, height 4): the trapezoidal side faces are the largest,
// (2 + 1)/2 * sqrt(4^2 + 0.5^2).
TEST(HexKernelTest, MaxFaceAreaOfFrustum)
{
  Hex h;
  for (unsigned int a = 0; a < 8; ++a)
    {
      const double half = corner(a, 2) ? 0.5 : 1.;
      h.x[a][0]         = corner(a, 0) ? half : -half;
      h.x[a][1]         = corner(a, 1) ? half : -half;
      h.x[a][2]         = 4. * corner(a, 2);
    }
  const double expected = 1.5 * std::sqrt(16.25);
  EXPECT_NEAR(hex_max_face_area(h.x), expected, 1e-14 * expected);
}

// Each of the six faces in turn is the unique largest one: a flat frustum (big face 2x2, opposite
// face 1x1, thickness 0.5, side faces 1.5 sqrt(0.5)) with the big face on that side, rotated.
TEST(HexKernelTest, MaxFaceAreaFindsEachFace)
{
  std::mt19937 rng(4);
  for (unsigned int k = 0; k < 3; ++k)
    for (unsigned int side = 0; side < 2; ++side)
      {
        Mat R;
        random_rotation(rng, R);
        Hex h;
        for (unsigned int a = 0; a < 8; ++a)
          {
            const double half = static_cast<unsigned int>(corner(a, k)) == side ? 1. : 0.5;
            double       p[3];
            for (unsigned int j = 0; j < 3; ++j)
              p[j] = j == k ? 0.5 * corner(a, j) : (corner(a, j) ? half : -half);
            for (unsigned int i = 0; i < 3; ++i)
              h.x[a][i] = R[i][0] * p[0] + R[i][1] * p[1] + R[i][2] * p[2];
          }
        double B[8][3];
        ASSERT_GT(hex_volume_gradient(h.x, B), 0.);
        EXPECT_NEAR(hex_max_face_area(h.x), 4., 4e-14) << "direction " << k << " side " << side;
      }
}

// Distorted hexahedra with warped faces: the largest magnitude of the face vector area
// int x_s x x_t ds dt, computed here per face from the node bits (exact by the midpoint rule,
// since x_s is linear in t and x_t linear in s).
TEST(HexKernelTest, MaxFaceAreaOfPerturbedHexIsLargestVectorArea)
{
  std::mt19937 rng(77);
  for (int trial = 0; trial < 100; ++trial)
    {
      const Hex h        = perturbed_hex(rng, 0.25);
      double    expected = 0;
      for (unsigned int k = 0; k < 3; ++k)
        for (unsigned int side = 0; side < 2; ++side)
          {
            const unsigned int j1 = (k + 1) % 3, j2 = (k + 2) % 3;
            double             xs[3] = {0, 0, 0}, xt[3] = {0, 0, 0};
            for (unsigned int a = 0; a < 8; ++a)
              if (static_cast<unsigned int>(corner(a, k)) == side)
                for (unsigned int i = 0; i < 3; ++i)
                  {
                    // Derivatives of the bilinear face map at the face centre.
                    xs[i] += 0.5 * (corner(a, j1) ? 1. : -1.) * h.x[a][i];
                    xt[i] += 0.5 * (corner(a, j2) ? 1. : -1.) * h.x[a][i];
                  }
            const double c[3] = {xs[1] * xt[2] - xs[2] * xt[1], xs[2] * xt[0] - xs[0] * xt[2],
                                 xs[0] * xt[1] - xs[1] * xt[0]};
            expected = std::max(expected, std::sqrt(c[0] * c[0] + c[1] * c[1] + c[2] * c[2]));
          }
      EXPECT_NEAR(hex_max_face_area(h.x), expected, 1e-13 * expected) << "trial " << trial;
    }
}

// --- 7. Hughes-Winget rotation -------------------------------------------------------------

// Q is a proper rotation for any spin and step, and equals the Cayley transform
// (I - dt W / 2)^-1 (I + dt W / 2) computed with an explicit inverse.
TEST(HexKernelTest, HughesWingetRotationIsOrthogonal)
{
  std::mt19937                           rng(13);
  std::normal_distribution<double>       n(0., 1.);
  std::uniform_real_distribution<double> log_dt(-8., 1.);
  for (int trial = 0; trial < 200; ++trial)
    {
      const double w[3] = {n(rng), n(rng), n(rng)};
      const double dt   = std::pow(10., log_dt(rng));
      Mat          W, Q;
      skew(w, W);
      hughes_winget_rotation(W, dt, Q);
      Mat QQt;
      for (unsigned int i = 0; i < 3; ++i)
        for (unsigned int j = 0; j < 3; ++j)
          {
            QQt[i][j] = 0;
            for (unsigned int k = 0; k < 3; ++k)
              QQt[i][j] += Q[i][k] * Q[j][k];
            EXPECT_NEAR(QQt[i][j], i == j ? 1. : 0., 1e-14) << "trial " << trial;
          }
      EXPECT_NEAR(det3(Q), 1., 1e-14) << "trial " << trial;

      Mat Minus, Plus;
      for (unsigned int i = 0; i < 3; ++i)
        for (unsigned int j = 0; j < 3; ++j)
          {
            Minus[i][j] = (i == j ? 1. : 0.) - 0.5 * dt * W[i][j];
            Plus[i][j]  = (i == j ? 1. : 0.) + 0.5 * dt * W[i][j];
          }
      // Inverse by cofactors: inv(M)_ij = cof(M)_ji / det M.
      const double detM = det3(Minus);
      Mat          inv;
      for (unsigned int i = 0; i < 3; ++i)
        for (unsigned int j = 0; j < 3; ++j)
          {
            const unsigned int i1 = (i + 1) % 3, i2 = (i + 2) % 3, j1 = (j + 1) % 3, j2 = (j + 2) % 3;
            inv[j][i] = (Minus[i1][j1] * Minus[i2][j2] - Minus[i1][j2] * Minus[i2][j1]) / detM;
          }
      Mat cayley;
      multiply(inv, Plus, cayley);
      EXPECT_LT(distance(Q, cayley), 1e-14) << "trial " << trial;
    }
}

// Constant spin W over time T in N steps: Q^N -> exp(W T) (Rodrigues), second order. Each Cayley
// step turns by 2 atan(theta / 2N) about the spin axis, so the error is the closed form
// |R(a) - R(b)|_F = 2 sqrt(2) |sin((a - b) / 2)|, which drops by a factor four when N doubles.
TEST(HexKernelTest, HughesWingetRotationConvergesToExponential)
{
  const double w[3] = {0.6, -1.0, 1.6}; // |w| = 1.98 rad/s
  const double T    = 1.0;
  const double theta = T * std::sqrt(w[0] * w[0] + w[1] * w[1] + w[2] * w[2]);
  Mat          W, exact;
  skew(w, W);
  rodrigues(w, T, exact);
  double previous = 0;
  for (unsigned int N = 8; N <= 256; N *= 2)
    {
      Mat Q, P = {{1, 0, 0}, {0, 1, 0}, {0, 0, 1}}, next;
      hughes_winget_rotation(W, T / N, Q);
      for (unsigned int k = 0; k < N; ++k)
        {
          multiply(Q, P, next);
          std::copy(&next[0][0], &next[0][0] + 9, &P[0][0]);
        }
      const double error     = distance(P, exact);
      const double lag       = theta - 2. * N * std::atan(theta / (2. * N));
      const double predicted = 2. * std::sqrt(2.) * std::abs(std::sin(0.5 * lag));
      EXPECT_NEAR(error, predicted, 1e-9 * predicted + 1e-13) << "N = " << N;
      if (previous > 0)
        {
          EXPECT_GT(previous / error, 3.9) << "N = " << N;
          EXPECT_LT(previous / error, 4.1) << "N = " << N;
        }
      previous = error;
    }
}

// rotate_symmetric(Q, s) = Q S Q^T (plain loops here), preserving trace and von Mises stress.
TEST(HexKernelTest, RotateSymmetricIsQSQt)
{
  std::mt19937                           rng(21);
  std::uniform_real_distribution<double> u(-1., 1.);
  for (int trial = 0; trial < 100; ++trial)
    {
      Mat Q;
      random_rotation(rng, Q);
      double s[6];
      for (double &c : s)
        c = 1e8 * u(rng);
      Mat S;
      unpack(s, S);
      Mat expected = {};
      for (unsigned int i = 0; i < 3; ++i)
        for (unsigned int j = 0; j < 3; ++j)
          for (unsigned int k = 0; k < 3; ++k)
            for (unsigned int l = 0; l < 3; ++l)
              expected[i][j] += Q[i][k] * S[k][l] * Q[j][l];
      const double trace = S[0][0] + S[1][1] + S[2][2], q = von_mises(S);
      rotate_symmetric(Q, s);
      Mat R;
      unpack(s, R);
      EXPECT_LT(distance(R, expected), 1e-14 * 1e9) << "trial " << trial;
      EXPECT_NEAR(R[0][0] + R[1][1] + R[2][2], trace, 1e-14 * 1e9) << "trial " << trial;
      EXPECT_NEAR(von_mises(R), q, 1e-14 * 1e9) << "trial " << trial;
    }
  // A quarter turn about z swaps xx and yy and flips the sign of xy, yz <-> xz.
  const Mat Rz    = {{0, -1, 0}, {1, 0, 0}, {0, 0, 1}};
  double    s[6]  = {1, 2, 3, 4, 5, 6};
  rotate_symmetric(Rz, s);
  const double expected[6] = {2, 1, 3, 5, -4, -6};
  for (unsigned int c = 0; c < 6; ++c)
    EXPECT_NEAR(s[c], expected[c], 1e-15) << "component " << c;
}
