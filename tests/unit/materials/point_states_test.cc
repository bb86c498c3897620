// SPDX-License-Identifier: LGPL-2.1-or-later
// The material-point path shared by HexForce and SpgForce (materials/point_states.h): groups
// and batches, history rows, one material call per batch against the elastic closed form, the
// trapezoid stress work in both summation orders, and the bulk viscosity with its step limit.
#include <shard/base/parameters.h>
#include <shard/materials/elastic.h>
#include <shard/materials/point_states.h>

#include <gtest/gtest.h>

#include <cmath>
#include <memory>
#include <vector>

namespace
{
  using namespace shard;
  using materials::Material;

  /// Elastic steel, E = 200 GPa, nu = 0.3, rho = 7850 (defaults written out).
  std::unique_ptr<Material>
  steel()
  {
    auto                     m = materials::create_material("elastic");
    dealii::ParameterHandler prm;
    m->declare_parameters(prm);
    prm.parse_input_from_string("set density = 7850\nset young's modulus = 200e9\nset poisson's ratio = 0.3\n");
    m->check_parameters(base::PrmSource(), "C - Materials/steel");
    m->prepare();
    return m;
  }
} // namespace

TEST(PointStates, GroupsAndBatches)
{
  const auto                        a = steel(), b = steel();
  materials::PointStates            points;
  std::vector<unsigned int>         group_of(150, 0);
  std::vector<double>               positions(3 * 150, 0.);
  for (unsigned int i = 100; i < 150; ++i)
    group_of[i] = 2; // group 1 is empty
  points.build({a.get(), b.get(), b.get()}, group_of, positions.data());
  ASSERT_EQ(points.size(), 150u);
  // 100 points in batches of 64: [0, 64), [64, 100); then [100, 150).
  const auto &batches = points.batches();
  ASSERT_EQ(batches.size(), 3u);
  EXPECT_EQ(batches[0].begin, 0u);
  EXPECT_EQ(batches[0].end, 64u);
  EXPECT_EQ(batches[1].end, 100u);
  EXPECT_EQ(batches[2].group, 2u);
  EXPECT_EQ(batches[2].begin, 100u);
  EXPECT_EQ(&points.material(120), b.get());
  EXPECT_EQ(points.groups()[1].begin, points.groups()[1].end);

  // Removing points keeps the order of the rest and their groups.
  std::vector<bool> drop(150, false);
  for (unsigned int i = 0; i < 150; i += 3)
    drop[i] = true;
  points.remove(drop);
  EXPECT_EQ(points.size(), 100u);
  EXPECT_EQ(points.groups()[0].end, 66u); // 100 - ceil(100 / 3)
  EXPECT_EQ(points.groups()[2].begin, 66u);
  EXPECT_EQ(&points.material(70), b.get());
  EXPECT_EQ(points.state_value(0, "no such slot"), 0.);
}

TEST(PointStates, OneCallPerBatchGivesTheElasticStress)
{
  // Uniaxial strain increment de_xx = 1e-4 with J = exp(1e-4) on 70 points: the elastic model's
  // pressure is K ln J and its deviator 2G dev(de), so sigma_xx = (K + 4G/3) de and
  // sigma_yy = sigma_zz = (K - 2G/3) de.
  const auto                m = steel();
  materials::PointStates    points;
  std::vector<unsigned int> group_of(70, 0);
  std::vector<double>       positions(3 * 70, 0.);
  points.build({m.get()}, group_of, positions.data());
  std::vector<double> stress(6 * 70, 0.), de(6 * 70, 0.), J(70, std::exp(1e-4)), length(70, 0.01), c(70, 0.);
  for (unsigned int k = 0; k < 70; ++k)
    de[6 * k] = 1e-4;
  for (const auto &b : points.batches())
    points.update(b, 1e-7, &de[6 * b.begin], &J[b.begin], &length[b.begin], stress.data(), &c[b.begin]);
  const double E = 200e9, nu = 0.3, K = E / (3 * (1 - 2 * nu)), G = E / (2 * (1 + nu));
  for (unsigned int k = 0; k < 70; ++k)
    {
      EXPECT_NEAR(stress[6 * k], (K + 4 * G / 3) * 1e-4, 1e-6 * K * 1e-4) << k;
      EXPECT_NEAR(stress[6 * k + 1], (K - 2 * G / 3) * 1e-4, 1e-6 * K * 1e-4) << k;
      EXPECT_NEAR(c[k], std::sqrt((K + 4 * G / 3) / 7850), 1e-3 * c[k]) << k;
    }
}

TEST(PointStates, StressWorkIsTheTrapezoidInBothOrders)
{
  // From zero stress to sigma = E' de in one step: W = V sigma de / 2.
  const double old_s[6] = {0, 0, 0, 0, 0, 0}, new_s[6] = {2e6, 1e6, 1e6, 3e5, 0, -2e5};
  const double de[6]    = {1e-4, 0, 0, 5e-5, 0, -2e-5};
  const double expected = 0.5 * 2e-6 * (2e6 * 1e-4 + 2 * 3e5 * 5e-5 + 2 * (-2e5) * (-2e-5));
  for (const auto order : {materials::WorkOrder::normal_then_shear, materials::WorkOrder::pairs})
    EXPECT_NEAR(materials::stress_work(old_s, new_s, de, 2e-6, order), expected, 1e-15 * std::abs(expected));
}

TEST(BulkViscosity, PressureWorkAndStep)
{
  const materials::BulkViscosity v{0.06, 1.5};
  const double rho = 2400, L = 0.01, c = 3000, dt = 1e-6, trd = -1e-3, V = 1e-6;
  // q = rho L (Q2 L r^2 - Q1 c r), r = tr(de) / dt = -1000 1/s.
  const double q = rho * L * (1.5 * L * 1e6 + 0.06 * c * 1e3);
  EXPECT_DOUBLE_EQ(v.pressure(rho, L, c, trd, dt), q);
  EXPECT_EQ(v.pressure(rho, L, c, -trd, dt), 0.); // expansion: none
  double q_old = 0, work = 1;
  EXPECT_DOUBLE_EQ(v.apply(rho, L, c, trd, dt, V, q_old, work), q);
  EXPECT_DOUBLE_EQ(q_old, q);
  EXPECT_DOUBLE_EQ(work, 1 - 0.5 * q * trd * V); // dissipated: the work grows in compression
  // Step: L / (c (sqrt(1 + r^2) + r)), r = Q1 in expansion, Q1 - Q2 L tr(de) / (dt c) in compression.
  EXPECT_DOUBLE_EQ(v.stable_step(L, c, -trd, dt), L / c / v.initial_step_factor());
  const double r = 0.06 + 1.5 * L * 1e3 / c;
  EXPECT_DOUBLE_EQ(v.stable_step(L, c, trd, dt), L / (c * (std::sqrt(1 + r * r) + r)));
  EXPECT_DOUBLE_EQ(v.initial_step_factor(), std::sqrt(1 + 0.06 * 0.06) + 0.06);
}
