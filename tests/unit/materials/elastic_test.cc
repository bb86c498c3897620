// SPDX-License-Identifier: LGPL-2.1-or-later
// Unit tests of the model "elastic" against closed forms (doc/manual/materials.md, "Tests").
#include <shard/base/parameters.h>
#include <shard/materials/elastic.h>
#include <shard/materials/material.h>

#include <gtest/gtest.h>

#include <cmath>
#include <memory>
#include <string>

namespace
{
  using namespace shard;
  using materials::Material;

  const std::string path = "C - Materials/steel";

  /// Declares @p model in `C - Materials/steel`, parses @p text there and checks the values.
  std::unique_ptr<Material>
  read(const std::string &model, const std::string &text)
  {
    std::unique_ptr<Material> material = materials::create_material(model);
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
  make(const std::string &model, const std::string &text = "")
  {
    std::unique_ptr<Material> material = read(model, text);
    material->prepare();
    return material;
  }

  /// Expects read() to throw base::InputError whose message names @p key.
  void
  expect_rejected(const std::string &model, const std::string &text, const std::string &key)
  {
    try
      {
        read(model, text);
        ADD_FAILURE() << "accepted: " << text;
      }
    catch (const base::InputError &error)
      {
        EXPECT_NE(std::string(error.what()).find(path + "/" + key), std::string::npos)
          << error.what();
      }
  }

  /// Moduli from E and nu, written out independently of the code.
  struct Moduli
  {
    double K, G;
  };
  Moduli
  moduli(const double E, const double nu)
  {
    return {E / (3. * (1. - 2. * nu)), E / (2. * (1. + nu))};
  }

  /// One point: 6 stresses, no history.
  struct Point
  {
    double stress[6] = {0., 0., 0., 0., 0., 0.};
    double wave_speed = 0.;

    void
    step(const Material &material, const double (&de)[6], const double J, const double dt = 1e-6)
    {
      materials::PointBatch batch;
      batch.n = 1;
      batch.dt = dt;
      const double h = 1e-3;
      batch.strain_increment = de;
      batch.relative_volume = &J;
      batch.characteristic_length = &h;
      batch.stress = stress;
      batch.state = nullptr;
      batch.wave_speed = &wave_speed;
      material.update(batch);
    }
  };

  void
  expect_relative(const double value, const double expected, const double tolerance)
  {
    EXPECT_NEAR(value, expected, tolerance * std::abs(expected)) << "expected " << expected;
  }
} // namespace

// Uniaxial strain e in xx with J = exp(e):
// sigma_xx = (K + 4G/3) e, sigma_yy = sigma_zz = (K - 2G/3) e.
TEST(ElasticTest, UniaxialStrainMatchesClosedForm)
{
  const auto   material = make("elastic");
  const Moduli m        = moduli(210e9, 0.3);
  for (const double e : {1e-4, -2e-3})
    {
      Point one;
      one.step(*material, {e, 0., 0., 0., 0., 0.}, std::exp(e));
      // The same strain in 10 steps: the hypoelastic deviator adds up linearly,
      // the pressure depends on the final J only.
      Point ten;
      for (int k = 1; k <= 10; ++k)
        ten.step(*material, {e / 10., 0., 0., 0., 0., 0.}, std::exp(e * k / 10.));
      for (const Point *p : {&one, &ten})
        {
          expect_relative(p->stress[0], (m.K + 4. / 3. * m.G) * e, 1e-12);
          expect_relative(p->stress[1], (m.K - 2. / 3. * m.G) * e, 1e-12);
          expect_relative(p->stress[2], (m.K - 2. / 3. * m.G) * e, 1e-12);
          for (int c = 3; c < 6; ++c)
            EXPECT_EQ(p->stress[c], 0.);
        }
    }
}

// Simple shear at J = 1 with tensor component eps_xy (storage slot 5): sigma_xy = 2 G eps_xy.
TEST(ElasticTest, SimpleShearMatchesClosedForm)
{
  const auto   material = make("elastic");
  const Moduli m        = moduli(210e9, 0.3);
  const double eps_xy   = 5e-4;
  Point        p;
  p.step(*material, {0., 0., 0., 0., 0., eps_xy}, 1.);
  expect_relative(p.stress[5], 2. * m.G * eps_xy, 1e-12);
  for (int c = 0; c < 5; ++c)
    EXPECT_NEAR(p.stress[c], 0., 1e-6);
}

// The pressure is -K ln J of the current J alone: the hydrostatic part of the incoming stress is
// replaced, its deviator kept.
TEST(ElasticTest, PressureComesFromRelativeVolume)
{
  const auto   material = make("elastic");
  const Moduli m        = moduli(210e9, 0.3);
  Point        p;
  const double in[6] = {-300e6, -100e6, 100e6, 10e6, 20e6, 30e6}; // mean -100e6
  std::copy(in, in + 6, p.stress);
  const double J = 0.97;
  p.step(*material, {0., 0., 0., 0., 0., 0.}, J);
  const double sig_vol = m.K * std::log(J);
  expect_relative(p.stress[0], -200e6 + sig_vol, 1e-12);
  expect_relative(p.stress[1], 0. + sig_vol, 1e-12);
  expect_relative(p.stress[2], 200e6 + sig_vol, 1e-12);
  EXPECT_DOUBLE_EQ(p.stress[3], 10e6);
  EXPECT_DOUBLE_EQ(p.stress[4], 20e6);
  EXPECT_DOUBLE_EQ(p.stress[5], 30e6);
}

// Wave speed sqrt((K + 4G/3)/rho0) for aluminium-like input read from the parameter text.
TEST(ElasticTest, WaveSpeedMatchesClosedForm)
{
  const auto material = make("elastic",
                             "set density = 2700\n"
                             "set young's modulus = 70e9\n"
                             "set poisson's ratio = 0.33\n");
  const Moduli m        = moduli(70e9, 0.33);
  const double expected = std::sqrt((m.K + 4. / 3. * m.G) / 2700.);
  EXPECT_DOUBLE_EQ(material->density(), 2700.);
  expect_relative(material->initial_wave_speed(), expected, 1e-14);
  Point p;
  p.step(*material, {1e-4, -2e-4, 0., 1e-5, 0., 0.}, 0.9999);
  expect_relative(p.wave_speed, expected, 1e-14);
  EXPECT_NEAR(expected, 6197.8, 0.1); // sqrt((68.627e9 + 4/3 26.316e9) / 2700)
}

TEST(ElasticTest, RejectsNegativeDensity)
{
  expect_rejected("elastic", "set density = -7850\n", "density");
}

TEST(ElasticTest, RejectsNonPositiveYoungsModulus)
{
  expect_rejected("elastic", "set young's modulus = 0\n", "young's modulus");
}

TEST(ElasticTest, RejectsPoissonRatioOutsideOpenRange)
{
  expect_rejected("elastic", "set poisson's ratio = 0.5\n", "poisson's ratio");
  expect_rejected("elastic", "set poisson's ratio = -1\n", "poisson's ratio");
}

TEST(ElasticTest, RegistryAndNoHistory)
{
  EXPECT_EQ(materials::material_model_names(), "elastic|von mises|kcc|rigid");
  EXPECT_TRUE(materials::create_material("no such model") == nullptr);
  const auto material = make("elastic");
  EXPECT_EQ(material->model_name(), "elastic");
  EXPECT_EQ(material->n_state_slots(), 0u);
  EXPECT_EQ(material->state_slot(materials::slot::plastic_strain), -1);
  EXPECT_FALSE(material->rigid());
  const auto rigid = make("rigid");
  EXPECT_EQ(rigid->model_name(), "rigid");
  EXPECT_TRUE(rigid->rigid());
  EXPECT_EQ(rigid->n_state_slots(), 0u);
}
