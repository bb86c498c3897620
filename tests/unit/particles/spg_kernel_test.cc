// SPDX-License-Identifier: LGPL-2.1-or-later
// The two-pass SPG kernel on random CSR stencils, against definitions written here:
// dense matrix products, the adjoint identity of the scatter and the passes, and the
// finite-difference gradient of a hyperelastic energy.
#include <shard/particles/spg_kernel.h>

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <random>
#include <vector>

namespace
{
  using shard::particles::CsrView;
  using shard::particles::SpgKernel;

  /// A random CSR matrix with about @p per_row entries per row; columns unique per row.
  struct RandomCsr
  {
    std::vector<unsigned int> offsets{0}, columns;
    std::vector<double>       values;
    unsigned int              rows, cols, width;

    RandomCsr(const unsigned int rows, const unsigned int cols, const unsigned int per_row,
              const unsigned int width, std::mt19937 &rng)
      : rows(rows)
      , cols(cols)
      , width(width)
    {
      std::uniform_real_distribution<double> value(-1., 1.);
      for (unsigned int r = 0; r < rows; ++r)
        {
          std::vector<unsigned int> picked;
          for (unsigned int k = 0; k < per_row; ++k)
            {
              const unsigned int c = rng() % cols;
              if (std::find(picked.begin(), picked.end(), c) == picked.end())
                picked.push_back(c);
            }
          for (const unsigned int c : picked)
            {
              columns.push_back(c);
              for (unsigned int w = 0; w < width; ++w)
                values.push_back(value(rng));
            }
          offsets.push_back(columns.size());
        }
    }

    CsrView
    view() const
    {
      return {rows, offsets.data(), columns.data(), values.data(), width};
    }

    /// Dense value (row, column, component); 0 where there is no entry.
    double
    dense(const unsigned int r, const unsigned int c, const unsigned int w) const
    {
      for (unsigned int e = offsets[r]; e < offsets[r + 1]; ++e)
        if (columns[e] == c)
          return values[width * e + w];
      return 0.;
    }
  };

  struct Problem
  {
    std::mt19937 rng{20261123};
    unsigned int n_k = 40, n_j = 35, n_i = 30;
    RandomCsr    a{n_j, n_k, 8, 1, rng};
    RandomCsr    g{n_i, n_j, 9, 3, rng};
    SpgKernel    kernel;

    Problem()
    {
      kernel.reinit(a.view(), g.view(), n_k);
    }

    std::vector<double>
    random_vector(const unsigned int n)
    {
      std::uniform_real_distribution<double> value(-1., 1.);
      std::vector<double>                    x(n);
      for (auto &v : x)
        v = value(rng);
      return x;
    }

    std::vector<double>
    deformation_gradient(const std::vector<double> &d) const
    {
      std::vector<double> u(3 * n_j), F(9 * n_i);
      kernel.interpolate(d.data(), u.data());
      kernel.deformation_gradient(u.data(), F.data());
      return F;
    }
  };

  /// St Venant-Kirchhoff: energy density and first Piola-Kirchhoff stress (row-major).
  double
  svk(const double *F, double *P)
  {
    const double lambda = 1.3, mu = 0.7;
    double       E[9], S[9];
    for (unsigned int a = 0; a < 3; ++a)
      for (unsigned int b = 0; b < 3; ++b)
        {
          double c = 0;
          for (unsigned int k = 0; k < 3; ++k)
            c += F[3 * k + a] * F[3 * k + b];
          E[3 * a + b] = 0.5 * (c - (a == b ? 1. : 0.));
        }
    const double tr = E[0] + E[4] + E[8];
    double       ee = 0;
    for (unsigned int k = 0; k < 9; ++k)
      {
        S[k] = 2 * mu * E[k] + (k % 4 == 0 ? lambda * tr : 0.);
        ee += E[k] * E[k];
      }
    for (unsigned int a = 0; a < 3; ++a)
      for (unsigned int b = 0; b < 3; ++b)
        {
          double p = 0;
          for (unsigned int k = 0; k < 3; ++k)
            p += F[3 * a + k] * S[3 * k + b];
          P[3 * a + b] = p;
        }
    return 0.5 * lambda * tr * tr + mu * ee;
  }
} // namespace

TEST(SpgKernelTest, PassesEqualDenseProducts)
{
  Problem             pb;
  const auto          d = pb.random_vector(3 * pb.n_k);
  std::vector<double> u(3 * pb.n_j);
  pb.kernel.interpolate(d.data(), u.data());
  const auto F = pb.deformation_gradient(d);
  std::vector<double> u_ref(3 * pb.n_j, 0.);
  for (unsigned int j = 0; j < pb.n_j; ++j)
    for (unsigned int k = 0; k < pb.n_k; ++k)
      for (unsigned int c = 0; c < 3; ++c)
        u_ref[3 * j + c] += pb.a.dense(j, k, 0) * d[3 * k + c];
  for (unsigned int n = 0; n < u.size(); ++n)
    EXPECT_NEAR(u[n], u_ref[n], 1e-13);
  for (unsigned int i = 0; i < pb.n_i; ++i)
    for (unsigned int a = 0; a < 3; ++a)
      for (unsigned int b = 0; b < 3; ++b)
        {
          double ref = a == b ? 1. : 0.;
          for (unsigned int j = 0; j < pb.n_j; ++j)
            ref += u_ref[3 * j + a] * pb.g.dense(i, j, b);
          EXPECT_NEAR(F[9 * i + 3 * a + b], ref, 1e-13);
        }
}

TEST(SpgKernelTest, ForceIsTheAdjointOfThePasses)
{
  // sum_K f_K . d_K = sum_I (V P)_I : (F_I(d) - I) for any d and V P: the scatters are the exact
  // transposes of the passes.
  Problem    pb;
  const auto d  = pb.random_vector(3 * pb.n_k);
  const auto vp = pb.random_vector(9 * pb.n_i);
  const auto F  = pb.deformation_gradient(d);
  std::vector<double> f(3 * pb.n_k);
  pb.kernel.internal_force(vp.data(), f.data());
  double lhs = 0, rhs = 0, scale = 0;
  for (unsigned int n = 0; n < f.size(); ++n)
    lhs += f[n] * d[n];
  for (unsigned int i = 0; i < pb.n_i; ++i)
    for (unsigned int k = 0; k < 9; ++k)
      {
        const double grad = F[9 * i + k] - (k % 4 == 0 ? 1. : 0.);
        rhs += vp[9 * i + k] * grad;
        scale += std::abs(vp[9 * i + k] * grad);
      }
  EXPECT_NEAR(lhs, rhs, 1e-13 * scale);
}

TEST(SpgKernelTest, ForceIsTheEnergyGradient)
{
  // f = dW/dd for W = sum_I V_I W(F_I), St Venant-Kirchhoff, against central differences.
  Problem    pb;
  auto       d = pb.random_vector(3 * pb.n_k);
  for (auto &x : d)
    x *= 0.05;
  std::vector<double> V(pb.n_i);
  for (unsigned int i = 0; i < pb.n_i; ++i)
    V[i] = 0.5 + 0.01 * i;
  const auto energy = [&](const std::vector<double> &dd) {
    const auto F = pb.deformation_gradient(dd);
    double     W = 0, P[9];
    for (unsigned int i = 0; i < pb.n_i; ++i)
      W += V[i] * svk(&F[9 * i], P);
    return W;
  };
  const auto          F = pb.deformation_gradient(d);
  std::vector<double> vp(9 * pb.n_i), f(3 * pb.n_k);
  for (unsigned int i = 0; i < pb.n_i; ++i)
    {
      svk(&F[9 * i], &vp[9 * i]);
      for (unsigned int k = 0; k < 9; ++k)
        vp[9 * i + k] *= V[i];
    }
  pb.kernel.internal_force(vp.data(), f.data());
  const double h = 1e-6;
  for (unsigned int n = 0; n < f.size(); ++n)
    {
      auto dp = d, dm = d;
      dp[n] += h;
      dm[n] -= h;
      const double fd = (energy(dp) - energy(dm)) / (2 * h);
      EXPECT_NEAR(f[n], fd, 1e-6 * (1 + std::abs(fd))) << "coefficient component " << n;
    }
}

TEST(SpgKernelTest, RejectsWrongWidthsAndColumns)
{
  Problem pb;
  EXPECT_THROW(pb.kernel.reinit(pb.g.view(), pb.a.view(), pb.n_k), std::invalid_argument);
  EXPECT_THROW(pb.kernel.reinit(pb.a.view(), pb.g.view(), 3), std::out_of_range);
}
