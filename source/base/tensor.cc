// SPDX-License-Identifier: LGPL-2.1-or-later
#include <shard/base/tensor.h>

#include <algorithm>
#include <cmath>

namespace shard::tensor
{
  void
  hughes_winget_rotation(const double (&W)[3][3], const double dt, double (&Q)[3][3])
  {
    // A = dt W / 2 = [a]x with axial vector a; Q = I + 2 / (1 + a.a) (A + A^2).
    const double a[3] = {0.5 * dt * W[2][1], 0.5 * dt * W[0][2], 0.5 * dt * W[1][0]};
    const double aa   = a[0] * a[0] + a[1] * a[1] + a[2] * a[2];
    const double c    = 2. / (1. + aa);
    const double A[3][3] = {{0, -a[2], a[1]}, {a[2], 0, -a[0]}, {-a[1], a[0], 0}};
    for (unsigned int i = 0; i < 3; ++i)
      for (unsigned int j = 0; j < 3; ++j)
        Q[i][j] = (i == j ? 1. : 0.) + c * (A[i][j] + a[i] * a[j] - (i == j ? aa : 0.));
  }

  void
  rotate_symmetric(const double (&Q)[3][3], double *s)
  {
    const double S[3][3] = {{s[0], s[5], s[4]}, {s[5], s[1], s[3]}, {s[4], s[3], s[2]}};
    double       T[3][3];
    for (unsigned int i = 0; i < 3; ++i)
      for (unsigned int j = 0; j < 3; ++j)
        T[i][j] = Q[i][0] * S[0][j] + Q[i][1] * S[1][j] + Q[i][2] * S[2][j];
    double R[3][3];
    for (unsigned int i = 0; i < 3; ++i)
      for (unsigned int j = i; j < 3; ++j)
        R[i][j] = T[i][0] * Q[j][0] + T[i][1] * Q[j][1] + T[i][2] * Q[j][2];
    s[0] = R[0][0];
    s[1] = R[1][1];
    s[2] = R[2][2];
    s[3] = R[1][2];
    s[4] = R[0][2];
    s[5] = R[0][1];
  }

  std::array<double, 3>
  symmetric_eigenvalues(const double *s)
  {
    const double p1 = s[3] * s[3] + s[4] * s[4] + s[5] * s[5];
    if (p1 == 0)
      {
        std::array<double, 3> d{{s[0], s[1], s[2]}};
        std::sort(d.begin(), d.end());
        return d;
      }
    const double m = (s[0] + s[1] + s[2]) / 3.;
    const double a = s[0] - m, b = s[1] - m, c = s[2] - m;
    const double p2 = a * a + b * b + c * c + 2. * p1;
    if (p2 <= 1e-30 * m * m)
      return {{m, m, m}};
    const double p = std::sqrt(p2 / 6.);
    // det(S - m I) / (2 p^3), the cosine of three times the angle.
    const double det = a * (b * c - s[3] * s[3]) - s[5] * (s[5] * c - s[3] * s[4]) + s[4] * (s[5] * s[3] - b * s[4]);
    const double phi = std::acos(std::clamp(det / (2. * p * p * p), -1., 1.)) / 3.;
    // m + 2 p cos(phi + 2 pi k / 3): k = 0 the largest, k = 1 the smallest.
    const double largest = m + 2. * p * std::cos(phi), smallest = m + 2. * p * std::cos(phi + 2. * M_PI / 3.);
    return {{smallest, 3. * m - largest - smallest, largest}};
  }

  std::array<double, 3>
  principal_stretches(const double *F)
  {
    const auto c = [F](const unsigned int a, const unsigned int b) {
      return F[a] * F[b] + F[3 + a] * F[3 + b] + F[6 + a] * F[6 + b];
    };
    const double C[6] = {c(0, 0), c(1, 1), c(2, 2), c(1, 2), c(0, 2), c(0, 1)};
    auto         l    = symmetric_eigenvalues(C);
    for (auto &x : l)
      x = std::sqrt(std::max(x, 0.));
    return l;
  }
} // namespace shard::tensor
