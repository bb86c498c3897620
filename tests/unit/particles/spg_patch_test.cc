// SPDX-License-Identifier: LGPL-2.1-or-later
// The RK stencils and the two-pass SPG kernel together, on an irregular 3-D particle block
// (free boundaries, every particle an integration point, Psi~ = Psi):
// - strain reproduction: a linear displacement field gives the exact constant deformation
//   gradient at every particle, boundary particles included;
// - rigid rotation gives an orthogonal F (so zero stress for any objective material);
// - the internal forces sum to zero for any stress field.
#include <shard/particles/neighbor_build.h>
#include <shard/particles/rk_shape.h>
#include <shard/particles/spg_kernel.h>

#include <gtest/gtest.h>

#include <cmath>
#include <random>
#include <vector>

namespace
{
  using namespace shard::particles;

  struct Block
  {
    std::vector<Point3> x;
    Stencil             stencil;
    SpgKernel           kernel;

    Block(const unsigned int n, const double h, const double dilation, const Support support)
    {
      std::mt19937                           rng(42);
      std::uniform_real_distribution<double> jitter(-0.3 * h, 0.3 * h);
      for (unsigned int k = 0; k < n; ++k)
        for (unsigned int j = 0; j < n; ++j)
          for (unsigned int i = 0; i < n; ++i)
            x.push_back(Point3{{i * h + jitter(rng), j * h + jitter(rng), k * h + jitter(rng)}});
      RkParameters params;
      params.dilation = dilation;
      params.support  = support;
      const std::vector<Point3> spacing(x.size(), Point3{{h, h, h}});
      const auto                radii     = support_radii_from_spacing(spacing, params);
      const auto                neighbors = find_support_neighbors(x, x, radii, support);
      stencil                             = build_rk_stencil(x, x, radii, neighbors, params);
      const CsrView a{stencil.n_rows(), stencil.row_offsets.data(), stencil.columns.data(), stencil.psi.data(), 1};
      const CsrView g{stencil.n_rows(), stencil.row_offsets.data(), stencil.columns.data(), stencil.grad.data(), 3};
      kernel.reinit(a, g, static_cast<unsigned int>(x.size()));
    }

    std::vector<double>
    deformation_gradient(const std::vector<double> &d) const
    {
      std::vector<double> u(3 * x.size()), F(9 * x.size());
      kernel.interpolate(d.data(), u.data());
      kernel.deformation_gradient(u.data(), F.data());
      return F;
    }
  };

  class SpgPatchTest : public ::testing::TestWithParam<std::tuple<double, Support>>
  {};
} // namespace

TEST_P(SpgPatchTest, LinearFieldGivesExactConstantGradientEverywhere)
{
  const auto [dilation, support] = GetParam();
  const Block b(6, 1e-3, dilation, support);
  const double H[3][3] = {{2e-3, -1e-3, 5e-4}, {3e-4, -1.5e-3, 7e-4}, {-6e-4, 2e-4, 1e-3}};
  const double c[3]    = {1e-5, -2e-5, 3e-5};
  std::vector<double> d(3 * b.x.size());
  for (unsigned int k = 0; k < b.x.size(); ++k)
    for (unsigned int i = 0; i < 3; ++i)
      d[3 * k + i] = c[i] + H[i][0] * b.x[k][0] + H[i][1] * b.x[k][1] + H[i][2] * b.x[k][2];
  const auto F = b.deformation_gradient(d);
  unsigned int fallback_rows = 0;
  for (const auto f : b.stencil.fallback)
    fallback_rows += f;
  ASSERT_EQ(fallback_rows, 0u) << "the block must be fully linear-consistent for this test";
  for (unsigned int p = 0; p < b.x.size(); ++p)
    for (unsigned int i = 0; i < 3; ++i)
      for (unsigned int j = 0; j < 3; ++j)
        EXPECT_NEAR(F[9 * p + 3 * i + j] - (i == j ? 1. : 0.), H[i][j], 1e-8 * 2e-3)
          << "particle " << p << " component " << i << j;
}

TEST_P(SpgPatchTest, RigidRotationGivesOrthogonalGradient)
{
  const auto [dilation, support] = GetParam();
  const Block b(6, 1e-3, dilation, support);
  // A finite rotation of 30 degrees about (1, 2, 3) (Rodrigues) plus a translation.
  const double angle = M_PI / 6, n0 = 1 / std::sqrt(14.), n[3] = {n0, 2 * n0, 3 * n0};
  double       R[3][3];
  for (unsigned int i = 0; i < 3; ++i)
    for (unsigned int j = 0; j < 3; ++j)
      {
        const double cross = (i == j) ? 0. : ((j == (i + 1) % 3) ? -n[3 - i - j] : n[3 - i - j]);
        R[i][j] = (i == j ? std::cos(angle) : 0.) + (1 - std::cos(angle)) * n[i] * n[j] + std::sin(angle) * cross;
      }
  std::vector<double> d(3 * b.x.size());
  for (unsigned int k = 0; k < b.x.size(); ++k)
    for (unsigned int i = 0; i < 3; ++i)
      d[3 * k + i] = R[i][0] * b.x[k][0] + R[i][1] * b.x[k][1] + R[i][2] * b.x[k][2] - b.x[k][i] + 1e-4;
  const auto F = b.deformation_gradient(d);
  for (unsigned int p = 0; p < b.x.size(); ++p)
    for (unsigned int i = 0; i < 3; ++i)
      for (unsigned int j = 0; j < 3; ++j)
        {
          EXPECT_NEAR(F[9 * p + 3 * i + j], R[i][j], 1e-10);
          // Green-Lagrange strain E = (F^T F - I)/2 vanishes, so does the stress of any
          // hyperelastic or objective material.
          double ftf = 0;
          for (unsigned int k = 0; k < 3; ++k)
            ftf += F[9 * p + 3 * k + i] * F[9 * p + 3 * k + j];
          EXPECT_NEAR(0.5 * (ftf - (i == j ? 1. : 0.)), 0., 1e-10);
        }
}

TEST_P(SpgPatchTest, InternalForcesSumToZero)
{
  const auto [dilation, support] = GetParam();
  const Block                            b(6, 1e-3, dilation, support);
  std::mt19937                           rng(7);
  std::uniform_real_distribution<double> stress(-1e8, 1e8);
  std::vector<double>                    vp(9 * b.x.size()), f(3 * b.x.size());
  for (auto &s : vp)
    s = stress(rng) * 1e-9; // V P with V = 1e-9 m^3
  b.kernel.internal_force(vp.data(), f.data());
  double sum[3] = {0, 0, 0}, scale = 0;
  for (unsigned int k = 0; k < b.x.size(); ++k)
    for (unsigned int i = 0; i < 3; ++i)
      {
        sum[i] += f[3 * k + i];
        scale += std::abs(f[3 * k + i]);
      }
  for (unsigned int i = 0; i < 3; ++i)
    EXPECT_NEAR(sum[i], 0., 1e-13 * scale);
}

INSTANTIATE_TEST_SUITE_P(Dilations, SpgPatchTest,
                         ::testing::Values(std::make_tuple(1.5, Support::box), std::make_tuple(2.5, Support::box),
                                           std::make_tuple(1.8, Support::sphere)));
