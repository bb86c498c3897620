// SPDX-License-Identifier: LGPL-2.1-or-later
// Unit tests of the model "von mises" against closed forms (doc/manual/materials.md, "Tests").
#include <shard/base/parameters.h>
#include <shard/materials/material.h>
#include <shard/materials/von_mises.h>

#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <memory>
#include <string>
#include <utility>
#include <vector>

namespace
{
  using namespace shard;
  using materials::Material;

  const std::string path  = "C - Materials/steel";
  const double      E     = 210e9; // defaults of the model
  const double      nu    = 0.3;
  const double      K     = E / (3. * (1. - 2. * nu));
  const double      G     = E / (2. * (1. + nu));
  const double      sqrt3 = std::sqrt(3.);

  /// Declares "von mises" in `C - Materials/steel`, parses @p text there and checks the values.
  std::unique_ptr<Material>
  read(const std::string &text)
  {
    std::unique_ptr<Material> material = materials::create_material("von mises");
    EXPECT_TRUE(material != nullptr);
    dealii::ParameterHandler prm;
    prm.enter_subsection("C - Materials");
    prm.enter_subsection("steel");
    material->declare_parameters(prm);
    prm.parse_input_from_string(text);
    prm.leave_subsection();
    prm.leave_subsection();
    material->check_parameters(base::PrmSource(), path);
    return material;
  }

  /// As read(), then prepare().
  std::unique_ptr<Material>
  make(const std::string &text)
  {
    std::unique_ptr<Material> material = read(text);
    material->prepare();
    return material;
  }

  /// Expects read() to throw base::InputError whose message names @p key and contains @p words.
  void
  expect_rejected(const std::string &text, const std::string &key, const std::string &words = "")
  {
    try
      {
        read(text);
        ADD_FAILURE() << "accepted: " << text;
      }
    catch (const base::InputError &error)
      {
        const std::string message = error.what();
        EXPECT_NE(message.find(path + "/" + key), std::string::npos) << message;
        EXPECT_NE(message.find(words), std::string::npos) << message;
      }
  }

  /// Piecewise-linear yield curve written out independently: rows (e_k, sigma_k), extended
  /// beyond the last row with the last slope (flat for one row).
  double
  curve(const std::vector<std::pair<double, double>> &rows, const double ep)
  {
    const std::size_t n = rows.size();
    if (n == 1)
      return rows[0].second;
    std::size_t k = 0;
    while (k + 2 < n && ep >= rows[k + 1].first)
      ++k;
    const double slope =
      (rows[k + 1].second - rows[k].second) / (rows[k + 1].first - rows[k].first);
    return rows[k].second + slope * (ep - rows[k].first);
  }

  std::string
  table_text(const std::vector<std::pair<double, double>> &rows)
  {
    std::string text;
    for (const auto &[e, s] : rows)
      text += (text.empty() ? "" : "; ") + std::to_string(e) + " " + std::to_string(s);
    return text;
  }

  /// One point with its history.
  struct Point
  {
    double stress[6]  = {0., 0., 0., 0., 0., 0.};
    double state[3]   = {0., 0., 0.};
    double wave_speed = 0.;

    void
    step(const Material &material, const double (&de)[6], const double J, const double dt = 1e-6)
    {
      materials::PointBatch batch;
      batch.n                     = 1;
      batch.dt                    = dt;
      const double h              = 1e-3;
      batch.strain_increment      = de;
      batch.relative_volume       = &J;
      batch.characteristic_length = &h;
      batch.stress                = stress;
      batch.state                 = state;
      batch.wave_speed            = &wave_speed;
      material.update(batch);
    }

    double
    plastic_strain() const
    {
      return state[0];
    }
    double
    failed() const
    {
      return state[1];
    }
    double
    strain_rate() const
    {
      return state[2];
    }
  };

  /// Pure shear at J = 1 from rest to the tensor component @p eps_xy in @p n equal steps.
  Point
  shear(const Material &material, const double eps_xy, const int n, const double dt = 1e-6)
  {
    Point p;
    for (int k = 0; k < n; ++k)
      p.step(material, {0., 0., 0., 0., 0., eps_xy / n}, 1., dt);
    return p;
  }

  void
  expect_relative(const double value, const double expected, const double tolerance)
  {
    EXPECT_NEAR(value, expected, tolerance * std::abs(expected)) << "expected " << expected;
  }

  /**
   * Pure shear: tau = sigma_y(e_p)/sqrt(3), eps_xy = tau/(2G) + (sqrt(3)/2) e_p. For each
   * plastic strain, drive the point to that eps_xy in 1 and in 1000 steps and compare.
   */
  void
  check_pure_shear(const std::vector<std::pair<double, double>> &rows,
                   const std::vector<double>                    &plastic_strains)
  {
    const auto material = make("set hardening table = " + table_text(rows) + "\n");
    // Elastic: half the shear strain at first yield.
    {
      const double eps_xy = 0.5 * rows[0].second / sqrt3 / (2. * G);
      const Point  p      = shear(*material, eps_xy, 1);
      expect_relative(p.stress[5], 2. * G * eps_xy, 1e-12);
      EXPECT_EQ(p.plastic_strain(), 0.);
    }
    for (const double ep : plastic_strains)
      {
        const double tau    = curve(rows, ep) / sqrt3;
        const double eps_xy = tau / (2. * G) + sqrt3 / 2. * ep;
        for (const int n : {1, 1000})
          {
            SCOPED_TRACE("e_p = " + std::to_string(ep) + ", steps = " + std::to_string(n));
            const Point p = shear(*material, eps_xy, n);
            expect_relative(p.stress[5], tau, 1e-10);
            expect_relative(p.plastic_strain(), ep, 1e-10);
            for (int c = 0; c < 5; ++c)
              EXPECT_NEAR(p.stress[c], 0., 1e-6);
            EXPECT_EQ(p.failed(), 0.);
          }
      }
  }
} // namespace

// Bilinear: 300 MPa, slope 1 GPa up to e_p = 0.2, then the same slope beyond the table.
TEST(VonMisesTest, PureShearBilinearMatchesClosedForm)
{
  check_pure_shear({{0., 300e6}, {0.2, 500e6}}, {1e-4, 0.05, 0.2, 0.4});
}

// Three segments with slopes 4, 1 and 0.2 GPa, then the last slope beyond e_p = 0.3;
// points on every segment and beyond; a one-step return crosses up to three segments.
TEST(VonMisesTest, PureShearThreeSegmentsMatchesClosedForm)
{
  check_pure_shear({{0., 400e6}, {0.02, 480e6}, {0.1, 560e6}, {0.3, 600e6}},
                   {0.01, 0.02, 0.05, 0.2, 0.3, 0.5});
}

// A single row: perfectly plastic, tau = sigma_y/sqrt(3) at any plastic strain.
TEST(VonMisesTest, PureShearPerfectlyPlasticMatchesClosedForm)
{
  check_pure_shear({{0., 400e6}}, {0.01, 0.7});
}

/**
 * Uniaxial strain e in xx, J = exp(e), linear hardening sigma_y = s0 + H e_p. With
 * t = sigma_xx - sigma_yy: elastic t = 2G e; plastic |t| = s0 + H e_p,
 * e_p = (2G|e| - s0)/(3G + H); sigma_xx = K e + 2t/3, sigma_yy = sigma_zz = K e - t/3.
 */
TEST(VonMisesTest, UniaxialStrainLinearHardeningMatchesClosedForm)
{
  const double s0 = 400e6, H = 1e9;
  const auto   material = make("set hardening table = 0 400e6; 0.1 500e6\n");
  for (const double e : {1e-3, 0.05, -1e-3, -0.05})
    {
      SCOPED_TRACE("e = " + std::to_string(e));
      const int n = 500;
      Point     p;
      for (int k = 1; k <= n; ++k)
        p.step(*material, {e / n, 0., 0., 0., 0., 0.}, std::exp(e * k / n));
      const bool   plastic = 2. * G * std::abs(e) > s0;
      const double ep      = plastic ? (2. * G * std::abs(e) - s0) / (3. * G + H) : 0.;
      const double t       = plastic ? std::copysign(s0 + H * ep, e) : 2. * G * e;
      EXPECT_EQ(plastic, std::abs(e) > 0.01);
      expect_relative(p.stress[0] - p.stress[1], t, 1e-10);
      expect_relative(p.stress[0], K * e + 2. / 3. * t, 1e-10);
      expect_relative(p.stress[1], K * e - t / 3., 1e-10);
      expect_relative(p.stress[2], K * e - t / 3., 1e-10);
      if (plastic)
        expect_relative(p.plastic_strain(), ep, 1e-10);
      else
        EXPECT_EQ(p.plastic_strain(), 0.);
    }
}

/**
 * Cowper-Symonds, flat curve 400 MPa, C = 40.4 1/s, P = 5: pure shear at a constant effective
 * rate r (d eps_xy/dt = r sqrt(3)/2) flows at sqrt(3) tau = R sigma_y, R = 1 + (r/C)^(1/P);
 * materials.md: R = 1.48, 2.20, 2.90 at 1, 100, 1000 1/s.
 */
TEST(VonMisesTest, CowperSymondsScalesFlowStress)
{
  const auto material = make("set hardening table = 0 400e6\n"
                             "set cowper symonds C = 40.4\n"
                             "set cowper symonds P = 5\n");
  const std::vector<std::pair<double, double>> rate_and_factor = {{1., 1.48},
                                                                  {100., 2.20},
                                                                  {1000., 2.90}};
  for (const auto &[rate, factor] : rate_and_factor)
    {
      SCOPED_TRACE("rate = " + std::to_string(rate));
      const double dt     = 1e-4 / rate;
      const int    n      = 200;
      const double eps_xy = n * rate * dt * sqrt3 / 2.;
      const Point  p      = shear(*material, eps_xy, n, dt);
      const double R      = 1. + std::pow(rate / 40.4, 1. / 5.);
      expect_relative(p.strain_rate(), rate, 1e-12);
      EXPECT_GT(p.plastic_strain(), 0.);
      expect_relative(sqrt3 * p.stress[5], R * 400e6, 1e-10);
      expect_relative(sqrt3 * p.stress[5] / 400e6, factor, 0.005);
    }
}

/**
 * The whole hardening curve is scaled by R: pure shear at a constant rate of 100 1/s on the
 * bilinear curve 300 MPa + 1 GPa e_p: tau = R (s0 + H e_p)/sqrt(3),
 * eps_xy = tau/(2G) + (sqrt(3)/2) e_p, so e_p = (eps_xy - R s0/(2 sqrt(3) G)) /
 * (R H/(2 sqrt(3) G) + sqrt(3)/2).
 */
TEST(VonMisesTest, CowperSymondsScalesHardeningCurve)
{
  const double s0 = 300e6, H = 1e9, rate = 100.;
  const auto   material = make("set hardening table = 0 300e6; 0.2 500e6\n"
                               "set cowper symonds C = 40.4\n"
                               "set cowper symonds P = 5\n");
  const double R        = 1. + std::pow(rate / 40.4, 1. / 5.);
  const double eps_xy   = 0.05;
  const int    n        = 1000;
  const double dt       = eps_xy / n / (rate * sqrt3 / 2.);
  const Point  p        = shear(*material, eps_xy, n, dt);
  const double ep = (eps_xy - R * s0 / (2. * sqrt3 * G)) / (R * H / (2. * sqrt3 * G) + sqrt3 / 2.);
  expect_relative(p.strain_rate(), rate, 1e-12);
  expect_relative(p.plastic_strain(), ep, 1e-10);
  expect_relative(p.stress[5], R * (s0 + H * ep) / sqrt3, 1e-10);
}

/**
 * Failure at e_p = 0.05: before, the point follows the hardening curve; from the step that
 * reaches 0.05 on, "failed" = 1, no deviatoric stress, no tension, compression -max(p, 0) I
 * with p = -K ln J.
 */
TEST(VonMisesTest, FailurePlasticStrainRemovesShearAndTension)
{
  const std::vector<std::pair<double, double>> rows = {{0., 400e6}, {1., 500e6}};
  const auto material = make("set hardening table = 0 400e6; 1 500e6\n"
                             "set failure plastic strain = 0.05\n");
  const auto strain_at = [&](const double ep) {
    return curve(rows, ep) / sqrt3 / (2. * G) + sqrt3 / 2. * ep;
  };

  // Below the limit: intact, on the curve.
  {
    const Point p = shear(*material, strain_at(0.04), 100);
    EXPECT_EQ(p.failed(), 0.);
    expect_relative(p.stress[5], curve(rows, 0.04) / sqrt3, 1e-10);
  }

  // Through the limit in steps of d eps_xy = 1e-5 (d e_p <= 2/sqrt(3) 1e-5).
  const double step = 1e-5;
  Point        p;
  double       eps_xy = 0.;
  while (p.failed() == 0. && eps_xy < strain_at(0.1))
    {
      p.step(*material, {0., 0., 0., 0., 0., step}, 1.);
      eps_xy += step;
    }
  EXPECT_EQ(p.failed(), 1.);
  EXPECT_GE(p.plastic_strain(), 0.05);
  EXPECT_LT(p.plastic_strain(), 0.05 + 2. / sqrt3 * step);
  EXPECT_GT(eps_xy, strain_at(0.05) - step);
  for (int c = 0; c < 6; ++c)
    EXPECT_EQ(p.stress[c], 0.);
  const double ep_failed = p.plastic_strain();

  // More shear with compression: pressure only.
  const double J_c = 0.98;
  p.step(*material, {0., 0., 0., 0., 0., 1e-3}, J_c);
  for (int c = 0; c < 3; ++c)
    expect_relative(p.stress[c], K * std::log(J_c), 1e-12);
  for (int c = 3; c < 6; ++c)
    EXPECT_EQ(p.stress[c], 0.);

  // Tension: nothing.
  p.step(*material, {0.02, 0., 0., 0., 0., 1e-3}, 1.02);
  for (int c = 0; c < 6; ++c)
    EXPECT_EQ(p.stress[c], 0.);

  // Failed for good, plastic strain frozen, compression carried again.
  p.step(*material, {-0.04, 0., 0., 0., 0., 0.}, J_c);
  EXPECT_EQ(p.failed(), 1.);
  EXPECT_EQ(p.plastic_strain(), ep_failed);
  expect_relative(p.stress[0], K * std::log(J_c), 1e-12);
  EXPECT_LT(p.stress[0], 0.);
}

// Without a limit (default 0) nothing fails at large plastic strain.
TEST(VonMisesTest, NoFailureByDefault)
{
  const auto  material = make("");
  const Point p        = shear(*material, 1., 100);
  EXPECT_EQ(p.failed(), 0.);
  EXPECT_GT(p.plastic_strain(), 1.);
}

TEST(VonMisesTest, SlotsWaveSpeedAndRegistry)
{
  const auto material = make("set density = 7830\n");
  EXPECT_EQ(material->model_name(), "von mises");
  const std::vector<std::string> names = {"effective plastic strain",
                                          "failed",
                                          "effective strain rate"};
  EXPECT_EQ(material->state_slot_names(), names);
  EXPECT_EQ(material->state_slot(materials::slot::plastic_strain), 0);
  EXPECT_EQ(material->state_slot(materials::slot::failed), 1);
  EXPECT_EQ(material->state_slot("effective strain rate"), 2);
  EXPECT_EQ(material->state_slot("damage"), -1);

  std::vector<double> state(4 * 3, std::numeric_limits<double>::quiet_NaN());
  material->initialize_state(4, state.data());
  for (const double s : state)
    EXPECT_EQ(s, 0.);

  const double c = std::sqrt((K + 4. / 3. * G) / 7830.);
  EXPECT_DOUBLE_EQ(material->density(), 7830.);
  expect_relative(material->initial_wave_speed(), c, 1e-14);
  Point p;
  p.step(*material, {0., 0., 0., 0., 0., 0.01}, 1.);
  expect_relative(p.wave_speed, c, 1e-14);
}

TEST(VonMisesTest, DefaultsAreAccepted)
{
  EXPECT_NO_THROW(read(""));
}

TEST(VonMisesTest, RejectsDecreasingYieldStress)
{
  expect_rejected("set hardening table = 0 500e6; 0.1 400e6\n",
                  "hardening table",
                  "yield stress must not decrease");
}

TEST(VonMisesTest, RejectsNonIncreasingPlasticStrain)
{
  expect_rejected("set hardening table = 0 400e6; 0.1 450e6; 0.1 460e6\n",
                  "hardening table",
                  "must be strictly increasing in plastic strain");
  expect_rejected("set hardening table = 0 400e6; 0.2 450e6; 0.1 460e6\n",
                  "hardening table",
                  "must be strictly increasing in plastic strain");
}

TEST(VonMisesTest, RejectsMalformedHardeningTable)
{
  expect_rejected("set hardening table = 0.01 400e6; 0.1 450e6\n",
                  "hardening table",
                  "must start at effective plastic strain 0");
  expect_rejected("set hardening table = 0 400e6; 0.1\n", "hardening table");
  expect_rejected("set hardening table = 0 400e6; 0.1 abc\n", "hardening table");
  expect_rejected("set hardening table = \n", "hardening table", "at least one row");
  expect_rejected("set hardening table = 0 0\n", "hardening table", "> 0");
}

TEST(VonMisesTest, RejectsNegativeDensity)
{
  expect_rejected("set density = -7850\n", "density", "> 0");
}

TEST(VonMisesTest, RejectsIncompressiblePoissonRatio)
{
  expect_rejected("set poisson's ratio = 0.5\n", "poisson's ratio", "0.5");
}

TEST(VonMisesTest, RejectsNonPositiveCowperSymondsP)
{
  expect_rejected("set cowper symonds P = 0\n", "cowper symonds P", "> 0");
}
