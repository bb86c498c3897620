// SPDX-License-Identifier: LGPL-2.1-or-later
/**
 * @file elastic.h
 * @brief Isotropic elasticity (shared by all metal models) and the model "elastic".
 * @ingroup materials
 *
 * Volumetric part hyperelastic, deviatoric part hypoelastic (doc/manual/materials.md):
 *   sigma = s - p I,  p = -K ln J,  s_new = dev(sigma_old) + 2 G dev(D dt).
 */
#pragma once

#include <shard/materials/material.h>

#include <string>
#include <vector>

namespace shard::materials
{
  namespace internal
  {
    /**
     * @brief Writes @p value as it would appear in a .prm file (up to 12 significant digits).
     * @param value The number to write.
     */
    std::string
    number_to_string(double value);

    /**
     * @brief Deviator of a symmetric tensor in the 6-component storage of material.h.
     * @param t The tensor (xx, yy, zz, yz, xz, xy).
     * @param d Out: t - tr(t)/3 I.
     */
    inline void
    deviator(const double *t, double *d)
    {
      const double mean = (t[0] + t[1] + t[2]) * (1. / 3.);
      d[0]              = t[0] - mean;
      d[1]              = t[1] - mean;
      d[2]              = t[2] - mean;
      d[3]              = t[3];
      d[4]              = t[4];
      d[5]              = t[5];
    }

    /**
     * @brief Double contraction a:b of two symmetric tensors in 6-component storage
     * (the off-diagonal terms count twice).
     * @param a First tensor.
     * @param b Second tensor.
     */
    inline double
    contract(const double *a, const double *b)
    {
      return a[0] * b[0] + a[1] * b[1] + a[2] * b[2] +
             2. * (a[3] * b[3] + a[4] * b[4] + a[5] * b[5]);
    }

    /**
     * @brief Hypoelastic trial deviator s* = dev(sigma_old) + 2 G dev(D dt).
     * @param stress Incoming stress sigma_old (6 components).
     * @param dev_increment The deviatoric strain increment dev(D dt) (6 components).
     * @param two_g Twice the shear modulus (Pa).
     * @param s Out: the trial deviator.
     */
    inline void
    trial_deviator(const double *stress, const double *dev_increment, const double two_g, double *s)
    {
      deviator(stress, s);
      for (unsigned int c = 0; c < n_sym; ++c)
        s[c] += two_g * dev_increment[c];
    }
  } // namespace internal

  /**
   * @brief The three isotropic elastic keys (density, Young's modulus, Poisson's ratio),
   * their checks and the derived moduli; a building block of Elastic, VonMises and later
   * metal models, so that every model reads and checks them the same way.
   *
   * The keys are bound to members of this object: it must not move after
   * declare_parameters() (it lives inside a Material that is held by pointer).
   */
  class IsotropicElasticity
  {
  public:
    /**
     * @brief Declares `density`, `young's modulus` and `poisson's ratio` in the current
     * subsection of @p prm, bound to members.
     * @param prm The parameter handler, already in the material's subsection.
     */
    void
    declare_parameters(dealii::ParameterHandler &prm);

    /**
     * @brief Checks density > 0, E > 0 and -1 < nu < 0.5.
     * @param source The input, to name file and line of a rejected key.
     * @param path The material's subsection, `C - Materials/<name>`.
     * @throws base::InputError naming the key and the allowed range.
     */
    void
    check_parameters(const base::PrmSource &source, const std::string &path) const;

    /// Computes K, G and the dilatational wave speed from the parsed keys.
    void
    prepare();

    /// Reference density rho0 (kg/m^3).
    double
    density() const
    {
      return density_;
    }

    /// Young's modulus E (Pa).
    double
    youngs_modulus() const
    {
      return youngs_modulus_;
    }

    /// Poisson's ratio nu (1).
    double
    poissons_ratio() const
    {
      return poissons_ratio_;
    }

    /// Bulk modulus K = E / (3 (1 - 2 nu)) (Pa); valid after prepare().
    double
    bulk_modulus() const
    {
      return bulk_modulus_;
    }

    /// Shear modulus G = E / (2 (1 + nu)) (Pa); valid after prepare().
    double
    shear_modulus() const
    {
      return shear_modulus_;
    }

    /// Dilatational wave speed sqrt((K + 4G/3) / rho0) (m/s); valid after prepare().
    double
    wave_speed() const
    {
      return wave_speed_;
    }

  private:
    double density_        = 7850.;
    double youngs_modulus_ = 210e9;
    double poissons_ratio_ = 0.3;

    double bulk_modulus_  = 0.;
    double shear_modulus_ = 0.;
    double wave_speed_    = 0.;
  };

  /**
   * @brief Isotropic elasticity for large strains and moderate elastic shear strains.
   *
   * Pressure p = -K ln J from the relative volume (hyperelastic, exact for any compression);
   * deviator updated hypoelastically, s_new = dev(sigma_old) + 2 G dev(D dt), where the caller
   * has already rotated sigma_old into the current frame. No history slots.
   */
  class Elastic : public Material
  {
  public:
    /// Returns "elastic".
    std::string
    model_name() const override;

    /**
     * @brief Declares density, young's modulus, poisson's ratio.
     * @param prm The parameter handler, already in `C - Materials/<name>`.
     */
    void
    declare_parameters(dealii::ParameterHandler &prm) override;

    /**
     * @brief Checks density > 0, E > 0, -1 < nu < 0.5.
     * @param source The input, to name file and line.
     * @param path `C - Materials/<name>`.
     */
    void
    check_parameters(const base::PrmSource &source, const std::string &path) const override;

    /// Computes K, G and the wave speed.
    void
    prepare() override;

    /// Reference density rho0 (kg/m^3).
    double
    density() const override;

    /// sqrt((K + 4G/3) / rho0) (m/s).
    double
    initial_wave_speed() const override;

    /// {K, G} of the undamaged material (Pa).
    std::array<double, 2>
    elastic_moduli() const override;

    /// No history: an empty list.
    std::vector<std::string>
    state_slot_names() const override;

    /**
     * @brief Elastic update of a batch.
     * @param batch Points; reads strain_increment, relative_volume and stress, writes stress
     *        and (if not null) wave_speed.
     */
    void
    update(const PointBatch &batch) const override;

    /// The elastic constants (for tests and derived quantities).
    const IsotropicElasticity &
    elasticity() const
    {
      return elasticity_;
    }

  private:
    IsotropicElasticity elasticity_;
  };

  /**
   * @brief A rigid FE body (model `rigid`; LS-DYNA's MAT_RIGID): the nodes of its elements
   * move as one rigid body under the sum of their forces (time::RigidBodies); the elements
   * carry no stress and limit no step. Density, Young's modulus and Poisson's ratio as for
   * `elastic`: the density gives the mass, the moduli the contact stiffness of its faces.
   * FE bodies only (not particles, not converted).
   */
  class Rigid : public Elastic
  {
  public:
    /// Returns "rigid".
    std::string
    model_name() const override;

    /// True.
    bool
    rigid() const override
    {
      return true;
    }

    /**
     * @brief Sets the stress of the batch to zero (never called by the FE loop, which skips
     * rigid bodies).
     * @param batch Points; writes stress and (if not null) wave_speed.
     */
    void
    update(const PointBatch &batch) const override;
  };
} // namespace shard::materials
