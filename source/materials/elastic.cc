// SPDX-License-Identifier: LGPL-2.1-or-later
/**
 * @file elastic.cc
 * @brief Isotropic elastic constants and the model "elastic".
 */
#include <shard/materials/elastic.h>

#include <algorithm>
#include <cmath>
#include <iomanip>
#include <sstream>

namespace shard::materials
{
  namespace internal
  {
    std::string
    number_to_string(const double value)
    {
      std::ostringstream out;
      out << std::setprecision(12) << value;
      return out.str();
    }
  } // namespace internal

  // --------------------------------------------------------------------------------------
  // IsotropicElasticity
  // --------------------------------------------------------------------------------------

  void
  IsotropicElasticity::declare_parameters(dealii::ParameterHandler &prm)
  {
    // Strict bounds (> 0, < 0.5) cannot be expressed by Patterns::Double, whose limits are
    // inclusive; check_parameters() owns these ranges so that every rejection of a key
    // carries the same message with unit and range.
    prm.add_parameter("density",
                      density_,
                      "Mass density in the reference configuration. Unit: kg/m^3. Range: > 0.",
                      dealii::Patterns::Double());
    prm.add_parameter("young's modulus",
                      youngs_modulus_,
                      "Young's modulus E of the isotropic elastic response. Unit: Pa. Range: > 0.",
                      dealii::Patterns::Double());
    prm.add_parameter("poisson's ratio",
                      poissons_ratio_,
                      "Poisson's ratio nu of the isotropic elastic response; with E it gives "
                      "K = E/(3(1-2nu)) and G = E/(2(1+nu)). Unit: 1. Range: -1 < nu < 0.5.",
                      dealii::Patterns::Double());
  }

  void
  IsotropicElasticity::check_parameters(const base::PrmSource &source,
                                        const std::string     &path) const
  {
    using internal::number_to_string;
    if (!(density_ > 0.) || !std::isfinite(density_))
      source.fail(path + "/density", number_to_string(density_), "must be > 0. Unit: kg/m^3");
    if (!(youngs_modulus_ > 0.) || !std::isfinite(youngs_modulus_))
      source.fail(path + "/young's modulus",
                  number_to_string(youngs_modulus_),
                  "must be > 0. Unit: Pa");
    if (!(poissons_ratio_ > -1. && poissons_ratio_ < 0.5))
      source.fail(path + "/poisson's ratio",
                  number_to_string(poissons_ratio_),
                  "must satisfy -1 < nu < 0.5 (0.5 is incompressible: K would be infinite). "
                  "Unit: 1");
  }

  void
  IsotropicElasticity::prepare()
  {
    bulk_modulus_  = youngs_modulus_ / (3. * (1. - 2. * poissons_ratio_));
    shear_modulus_ = youngs_modulus_ / (2. * (1. + poissons_ratio_));
    wave_speed_    = std::sqrt((bulk_modulus_ + 4. / 3. * shear_modulus_) / density_);
  }

  // --------------------------------------------------------------------------------------
  // Elastic
  // --------------------------------------------------------------------------------------

  std::string
  Elastic::model_name() const
  {
    return "elastic";
  }

  void
  Elastic::declare_parameters(dealii::ParameterHandler &prm)
  {
    elasticity_.declare_parameters(prm);
  }

  void
  Elastic::check_parameters(const base::PrmSource &source, const std::string &path) const
  {
    elasticity_.check_parameters(source, path);
  }

  void
  Elastic::prepare()
  {
    elasticity_.prepare();
  }

  double
  Elastic::density() const
  {
    return elasticity_.density();
  }

  double
  Elastic::initial_wave_speed() const
  {
    return elasticity_.wave_speed();
  }

  std::array<double, 2>
  Elastic::elastic_moduli() const
  {
    return {{elasticity_.bulk_modulus(), elasticity_.shear_modulus()}};
  }

  std::vector<std::string>
  Elastic::state_slot_names() const
  {
    return {};
  }

  void
  Elastic::update(const PointBatch &batch) const
  {
    const double       bulk  = elasticity_.bulk_modulus();
    const double       two_g = 2. * elasticity_.shear_modulus();
    const unsigned int n     = batch.n;

    const double *__restrict de_all = batch.strain_increment;
    const double *__restrict j_all  = batch.relative_volume;
    double *__restrict sig_all      = batch.stress;

    for (unsigned int i = 0; i < n; ++i)
      {
        const double *de  = de_all + n_sym * i;
        double       *sig = sig_all + n_sym * i;

        double d[n_sym], s[n_sym];
        internal::deviator(de, d);
        internal::trial_deviator(sig, d, two_g, s);
        const double sig_vol = bulk * std::log(j_all[i]); // = -p

        sig[0] = s[0] + sig_vol;
        sig[1] = s[1] + sig_vol;
        sig[2] = s[2] + sig_vol;
        sig[3] = s[3];
        sig[4] = s[4];
        sig[5] = s[5];
      }

    if (batch.wave_speed != nullptr)
      std::fill(batch.wave_speed, batch.wave_speed + n, elasticity_.wave_speed());
  }

  // --------------------------------------------------------------------------------------
  // Rigid
  // --------------------------------------------------------------------------------------

  std::string
  Rigid::model_name() const
  {
    return "rigid";
  }

  void
  Rigid::update(const PointBatch &batch) const
  {
    std::fill(batch.stress, batch.stress + 6 * batch.n, 0.);
    if (batch.wave_speed)
      std::fill(batch.wave_speed, batch.wave_speed + batch.n, initial_wave_speed());
  }
} // namespace shard::materials
