// SPDX-License-Identifier: LGPL-2.1-or-later
/**
 * @file von_mises.h
 * @brief The model "von mises": J2 plasticity with multi-linear isotropic hardening,
 *        Cowper-Symonds rate scaling and an optional plastic-strain failure limit.
 * @ingroup materials
 *
 * Theory and keys: doc/manual/materials.md; algorithm: design/materials.md section 9.
 */
#pragma once

#include <shard/materials/elastic.h>
#include <shard/materials/material.h>

#include <string>
#include <vector>

namespace shard::materials
{
  /**
   * @brief Von Mises plasticity with a piecewise-linear hardening table, exact radial return.
   *
   * Elasticity as in Elastic: p = -K ln J, hypoelastic deviator. The flow stress is
   * R sigma_y(e_p), where sigma_y is the table (continued beyond its last point with the last
   * slope, flat for a one-row table) and R = 1 + (rate/C)^(1/P) the Cowper-Symonds factor of
   * the total effective deviatoric strain rate (R = 1 when C = 0). The return walks the
   * table's linear segments and is exact (no iteration).
   *
   * Failure: once the effective plastic strain reaches `failure plastic strain` (when > 0),
   * slot "failed" becomes 1 for good; from then on the point carries neither deviatoric stress
   * nor tension, only the compressive pressure: sigma = -max(p, 0) I.
   *
   * History slots: "effective plastic strain" (1), "failed" (0 or 1),
   * "effective strain rate" (1/s, total effective deviatoric rate of the last step).
   */
  class VonMises : public Material
  {
  public:
    /// Slot index of the effective plastic strain.
    static constexpr unsigned int slot_plastic_strain = 0;
    /// Slot index of the failure flag.
    static constexpr unsigned int slot_failed = 1;
    /// Slot index of the effective strain rate.
    static constexpr unsigned int slot_strain_rate = 2;
    /// Number of history slots.
    static constexpr unsigned int n_slots = 3;

    /// Returns "von mises".
    std::string
    model_name() const override;

    /**
     * @brief Declares the elastic keys, `hardening table`, `cowper symonds C`,
     * `cowper symonds P` and `failure plastic strain`.
     * @param prm The parameter handler, already in `C - Materials/<name>`.
     */
    void
    declare_parameters(dealii::ParameterHandler &prm) override;

    /**
     * @brief Checks the elastic keys, the hardening table (parses, first strain 0, strains
     * strictly increasing, yield stresses > 0 and non-decreasing) and the rate and failure keys.
     * @param source The input, to name file and line.
     * @param path `C - Materials/<name>`.
     * @throws base::InputError naming the key and the requirement.
     */
    void
    check_parameters(const base::PrmSource &source, const std::string &path) const override;

    /// Computes the moduli and the segment table (strains, stresses, slopes).
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

    /// "effective plastic strain", "failed", "effective strain rate".
    std::vector<std::string>
    state_slot_names() const override;

    /**
     * @brief Elastic-plastic update of a batch by radial return.
     * @param batch Points; reads strain_increment, relative_volume, stress, state and dt;
     *        writes stress, state and (if not null) wave_speed.
     */
    void
    update(const PointBatch &batch) const override;

    /**
     * @brief Rate-independent yield stress sigma_y(e_p) of the prepared table (Pa).
     * @param plastic_strain Effective plastic strain e_p >= 0.
     */
    double
    yield_stress(double plastic_strain) const;

    /**
     * @brief Cowper-Symonds factor R = 1 + (rate/C)^(1/P), or 1 if C = 0 or rate <= 0.
     * @param strain_rate Effective strain rate (1/s).
     */
    double
    rate_factor(double strain_rate) const;

    /// The elastic constants.
    const IsotropicElasticity &
    elasticity() const
    {
      return elasticity_;
    }

  private:
    IsotropicElasticity elasticity_;

    std::string hardening_table_        = "0 400e6; 1 500e6";
    double      cowper_symonds_c_       = 0.;
    double      cowper_symonds_p_       = 5.;
    double      failure_plastic_strain_ = 0.;

    // Derived in prepare(): segment k starts at strain_[k] with stress stress_[k] and slope
    // slope_[k]; the last segment is open-ended (slope of the previous one, 0 for one row).
    std::vector<double> strain_;
    std::vector<double> stress_;
    std::vector<double> slope_;
  };
} // namespace shard::materials
