// SPDX-License-Identifier: LGPL-2.1-or-later
// Largest principal value used by the principal stress and strain bond criteria
// (tensor::symmetric_eigenvalues, shared with the particles' stable step).
#include <shard/base/tensor.h>

#include <gtest/gtest.h>

#include <cmath>
#include <random>

namespace
{
  double
  largest_eigenvalue(const double *s)
  {
    return shard::tensor::symmetric_eigenvalues(s)[2];
  }

  TEST(BondFailure, LargestEigenvalueDiagonal)
  {
    const double s[6] = {-3., 7., 2., 0., 0., 0.};
    EXPECT_DOUBLE_EQ(largest_eigenvalue(s), 7.);
    const double t[6] = {-5., -5., -5., 0., 0., 0.};
    EXPECT_DOUBLE_EQ(largest_eigenvalue(t), -5.);
  }

  TEST(BondFailure, LargestEigenvalueRotated)
  {
    // Q diag(4, 1, -2) Q^T with Q a rotation: the largest eigenvalue is 4 whatever Q is.
    std::mt19937                           gen(5);
    std::uniform_real_distribution<double> angle(0., 2. * M_PI);
    for (int trial = 0; trial < 200; ++trial)
      {
        const double a = angle(gen), b = angle(gen), c = angle(gen);
        const double Rz[3][3] = {{std::cos(a), -std::sin(a), 0}, {std::sin(a), std::cos(a), 0}, {0, 0, 1}};
        const double Ry[3][3] = {{std::cos(b), 0, std::sin(b)}, {0, 1, 0}, {-std::sin(b), 0, std::cos(b)}};
        const double Rx[3][3] = {{1, 0, 0}, {0, std::cos(c), -std::sin(c)}, {0, std::sin(c), std::cos(c)}};
        double       Q[3][3] = {}, T[3][3] = {};
        for (int i = 0; i < 3; ++i)
          for (int j = 0; j < 3; ++j)
            for (int k = 0; k < 3; ++k)
              T[i][j] += Rz[i][k] * Ry[k][j];
        for (int i = 0; i < 3; ++i)
          for (int j = 0; j < 3; ++j)
            for (int k = 0; k < 3; ++k)
              Q[i][j] += T[i][k] * Rx[k][j];
        const double d[3] = {4., 1., -2.};
        double       S[3][3] = {};
        for (int i = 0; i < 3; ++i)
          for (int j = 0; j < 3; ++j)
            for (int k = 0; k < 3; ++k)
              S[i][j] += Q[i][k] * d[k] * Q[j][k];
        const double s[6] = {S[0][0], S[1][1], S[2][2], S[1][2], S[0][2], S[0][1]};
        EXPECT_NEAR(largest_eigenvalue(s), 4., 1e-12);
        const auto all = shard::tensor::symmetric_eigenvalues(s);
        EXPECT_NEAR(all[0], -2., 1e-12);
        EXPECT_NEAR(all[1], 1., 1e-12);
        // F = Q diag(1.2, 0.9, 1.0): principal stretches 0.9, 1.0, 1.2 whatever Q is.
        const double stretch[3] = {1.2, 0.9, 1.0};
        double       F[9];
        for (int i = 0; i < 3; ++i)
          for (int j = 0; j < 3; ++j)
            F[3 * i + j] = Q[i][j] * stretch[j];
        const auto l = shard::tensor::principal_stretches(F);
        EXPECT_NEAR(l[0], 0.9, 1e-12);
        EXPECT_NEAR(l[1], 1.0, 1e-12);
        EXPECT_NEAR(l[2], 1.2, 1e-12);
      }
  }

  TEST(BondFailure, LargestEigenvalueRepeated)
  {
    // Uniaxial tension 100 plus hydrostatic -30: eigenvalues 70, -30, -30, rotated about z.
    const double c = std::cos(0.3), s = std::sin(0.3);
    const double t[6] = {-30. + 100. * c * c, -30. + 100. * s * s, -30., 0., 0., 100. * c * s};
    EXPECT_NEAR(largest_eigenvalue(t), 70., 1e-12);
  }
} // namespace
