// SPDX-License-Identifier: LGPL-2.1-or-later
/**
 * @file kcc.h
 * @brief The model "kcc": the K&C concrete model (Release III) with a tabulated compaction
 *        EOS, radial rate enhancement and parameters generated from f'c.
 * @ingroup materials
 *
 * Theory, every parameter and the decisions on the open points: doc/materials/kcc.md;
 * formulas: design/materials.md sections 1-8. Sign conventions: stress tension positive,
 * pressure p = -tr(sigma)/3 compression positive, q = sqrt(3 J2), Lode angle theta in
 * [0, pi/3] with theta = 0 on the tensile meridian.
 */
#pragma once

#include <shard/materials/compaction_eos.h>
#include <shard/materials/material.h>
#include <shard/materials/strength_field.h>

#include <array>
#include <iosfwd>
#include <string>
#include <vector>

namespace shard::materials
{
  /**
   * @brief The resolved parameter set of one K&C concrete (SI units): generated from f'c
   * where the input says `auto`, taken from the input otherwise.
   */
  struct KccParameters
  {
    /// Reference density (kg/m^3).
    double density = 2400.;
    /// Poisson's ratio (1).
    double poissons_ratio = 0.19;
    /// Unconfined compressive strength f'c as input (Pa).
    double compressive_strength = 48e6;
    /// Uniaxial tensile strength f't (Pa).
    double tensile_strength = 0.;
    /// Maximum surface a0 (Pa), a1 (1), a2 (1/Pa).
    double a0 = 0., a1 = 0., a2 = 0.;
    /// Yield surface a0y (Pa), a1y (1), a2y (1/Pa).
    double a0y = 0., a1y = 0., a2y = 0.;
    /// Residual surface a1f (1), a2f (1/Pa).
    double a1f = 0., a2f = 0.;
    /// Damage exponents b1 (compression), b2 (tension), b3 (volumetric damage).
    double b1 = 0., b2 = 0., b3 = 0.;
    /// Associativity omega (1) and its post-peak decay exponent EDROP (1).
    double omega = 0., edrop = 1.;
    /// Damage table: lambda_i (1), eta_i (1).
    std::vector<double> lambda, eta;
    /// EOS rows: volumetric strain ln(V/V0) (1), loading pressure (Pa), unloading modulus (Pa).
    std::vector<double> eos_strain, eos_pressure, eos_modulus;
    /// Shear modulus override (Pa); 0: G from the current unloading bulk modulus and nu.
    double shear_modulus = 0.;
    /// Rate enhancement on or off.
    bool rate_effects = true;
    /// DIF tables (rate 1/s, DIF); empty: the built-in CEB-FIP / Malvar-Ross curves.
    std::vector<double> dif_c_rate, dif_c, dif_t_rate, dif_t;
    /// Caps of the DIF (0: none).
    double dif_c_cap = 0., dif_t_cap = 0.;
    /// Localization width (m); 0: no size regularization.
    double localization_width = 0.;
    /// Scaled damage at which slot "failed" becomes 1 (0: never).
    double failure_scaled_damage = 0.;
    /// Weibull modulus of the strength field (0: uniform strength), see StrengthField.
    double strength_modulus = 0.;
    /// Cell size of the strength field (m).
    double strength_cell_size = 0.01;
    /// Seed of the strength field.
    unsigned int strength_seed = 1;

    // Derived in prepare():
    /// f'c at which the maximum surface passes through unconfined compression (Pa).
    double fc = 0.;
    /// f'yc at which the yield surface passes through unconfined compression (Pa).
    double fyc = 0.;
    /// psi at unconfined (p = f'c/3) and equal-biaxial (p = 2 alpha f'c/3) compression.
    double psi_uc = 0., psi_bc = 0.;
    /// lambda_m: the abscissa where eta reaches 1.
    double lambda_m = 0.;
  };

  /**
   * @brief K&C concrete, Release III.
   *
   * Three fixed surfaces (maximum, yield, residual) with their low-pressure and tension
   * branches, the Willam-Warnke Lode factor with psi(p), damage lambda with b1/b2/b3 and the
   * eta(lambda) table, partial associativity omega, radial rate enhancement and a tabulated
   * compaction EOS. The return at fixed trial pressure is exact: the current surface is
   * linear in eta and eta is piecewise linear in lambda, so the consistency equation is
   * solved segment by segment without iteration.
   *
   * History slots (in order): "effective plastic strain" (deviatoric), "failed" (scaled
   * damage above `failure scaled damage`, an indicator only), "damage lambda", "scaled damage"
   * (delta: 0 intact, 1 at the peak, 2 residual), "plastic volumetric strain" (expansion
   * positive), "max compaction" (EOS x_max), "effective strain rate" (1/s), "rate factor"
   * (r_f of the last step), "strength factor" (s of the strength field at the point's reference
   * position, 1 without a field: every surface is scaled by r_f s).
   */
  class KccConcrete : public Material
  {
  public:
    /// Slot indices.
    enum Slot : unsigned int
    {
      slot_plastic_strain = 0,
      slot_failed,
      slot_lambda,
      slot_delta,
      slot_plastic_volume,
      slot_max_compaction,
      slot_strain_rate,
      slot_rate_factor,
      slot_strength,
      n_slots
    };

    /// Returns "kcc".
    std::string
    model_name() const override;

    /**
     * @brief Declares density, poisson's ratio, compressive strength, the generated keys
     * (`auto` or a value) and the rate, regularization and failure keys.
     */
    void
    declare_parameters(dealii::ParameterHandler &prm) override;

    /**
     * @brief Parses the `auto`-or-value keys and the tables and checks every range, the
     * existence of f'c and f'yc on the surfaces and the EOS table.
     */
    void
    check_parameters(const base::PrmSource &source, const std::string &path) const override;

    /// Resolves the parameter set (generation from f'c) and builds the derived data.
    void
    prepare() override;

    /// Reference density (kg/m^3).
    double
    density() const override;

    /// sqrt((K0 + 4 G0/3)/rho) with K0 the first unloading modulus (m/s).
    double
    initial_wave_speed() const override;

    /// {K, G} of the undamaged material (Pa).
    std::array<double, 2>
    elastic_moduli() const override;

    /// The nine slot names, see the class documentation.
    std::vector<std::string>
    state_slot_names() const override;

    /// Zero history, rate factor and strength factor 1.
    void
    initialize_state(unsigned int n, double *state) const override;

    /// Writes the strength factor of the strength field at each reference position.
    void
    set_position_fields(unsigned int n, const double *positions, double *state) const override;

    /// The strength field of the resolved parameters.
    const StrengthField &
    strength_field() const
    {
      return field_;
    }

    /**
     * @brief Stress update of a batch (design/materials.md section 5, with the decisions of
     * doc/materials/kcc.md).
     */
    void
    update(const PointBatch &batch) const override;

    /// Writes the resolved parameter set as a .prm subsection body (every key `set`).
    void
    write_resolved_parameters(std::ostream &out) const override;

    /**
     * @brief Resolves @p input: every field equal to NaN (scalars) or empty (tables) is
     * generated from compressive_strength (design/materials.md section 7), then the derived
     * fields are computed. Throws std::invalid_argument if a surface has no f'c or f'yc.
     */
    static KccParameters
    resolve(KccParameters input);

    /// Sets a resolved parameter set directly (unit tests, the material driver).
    void
    set_parameters(const KccParameters &parameters);

    /// The resolved parameters.
    const KccParameters &
    parameters() const
    {
      return par_;
    }

    /// The EOS.
    const CompactionEos &
    eos() const
    {
      return eos_;
    }

    /// @name The model's functions (static strength, r_f = 1; p is compression positive, Pa)
    /// @{
    /// Maximum surface Delta sigma_m(p) (Pa).
    double
    max_surface(double p) const;
    /// Yield surface Delta sigma_y(p) (Pa).
    double
    yield_surface(double p) const;
    /// Residual surface Delta sigma_r(p) (Pa), 0 for p < 0.
    double
    residual_surface(double p) const;
    /// psi(p) = r_t / r_c, piecewise linear.
    double
    psi(double p) const;
    /**
     * @brief Willam-Warnke factor r'(theta, psi): psi at theta = 0 (tensile meridian),
     * 1 at theta = pi/3 (compressive meridian).
     * @param cos_theta cos(theta), theta in [0, pi/3].
     * @param psi The meridian ratio, 0.5 <= psi <= 1.
     */
    static double
    willam_warnke(double cos_theta, double psi);
    /// eta(lambda) of the table, with post-peak abscissae stretched by @p stretch.
    double
    eta(double lambda, double stretch = 1.) const;
    /**
     * @brief Current compressive-meridian strength r_f Delta sigma(p/r_f, lambda) (Pa),
     * including the damaged tension branch 3(p + eta f't) after the peak.
     */
    double
    current_surface(double p, double lambda, double rate_factor, double stretch = 1.) const;
    /// Hydrostatic tensile limit p_min (Pa, negative): -r_f f't, or -eta r_f f't after the peak.
    double
    tensile_limit(double lambda, double rate_factor, double stretch = 1.) const;
    /// Scaled damage delta: 2 lambda/(lambda + lambda_m) before the peak, 2 - eta after it.
    double
    scaled_damage(double lambda, double stretch = 1.) const;
    /// Dynamic increase factor for the effective strain rate @p rate (1/s).
    double
    dynamic_increase_factor(double rate, bool tension) const;
    /**
     * @brief cos(theta) of the Lode angle of a deviator, theta in [0, pi/3] with theta = 0 on
     * the tensile meridian: cos 3 theta = (3 sqrt 3 / 2) J3 / J2^(3/2) for tension-positive
     * stress; 0.5 (theta = pi/3, r' = 1) when J2 = 0.
     * @param s Deviator, 6 components.
     */
    static double
    cos_lode_angle(const double *s);
    /// Shear modulus for an unloading bulk modulus @p bulk (Pa).
    double
    shear_modulus(double bulk) const;
    /// @}

    /**
     * @brief The built-in DIF curves: compression CEB-FIP MC90, tension Malvar & Ross 1998
     * (design/materials.md section 6), both >= 1, no cap.
     * @param rate Effective strain rate (1/s).
     * @param fc Compressive strength (Pa).
     * @param tension Tension curve if true.
     */
    static double
    default_dif(double rate, double fc, bool tension);

  private:
    /**
     * @brief Stress update of one point over one (sub-)increment of a step.
     * @param de Strain increment (6).
     * @param ev Logarithmic volumetric strain ln J at the end of the increment.
     * @param rate Effective strain rate of the whole step (1/s).
     * @param rate_factor Rate factor to use; 0 takes it from @p rate and the trial pressure.
     * @param stretch Post-peak stretch w/h of the damage table (1 without regularization).
     * @param sig In: stress at the start; out: at the end (Pa).
     * @param st History slots of the point (in/out).
     * @return Dilatational wave speed of the final state (m/s).
     *
     * @note A long compute kernel on purpose (about 230 lines, one of the two functions of
     * source/ above the 150-line limit of issue 27; doc/manual/architecture.md, "Long
     * functions"): the update of one material point, whose branches of the K&C model (EOS and
     * trial state, rate factor, return to the failure surface with the dilatancy coupled in,
     * tension cutoff, damage and history) read and write the same local state; it is kept as
     * one function so that the model reads in one place.
     */
    double
    update_point(const double *de,
                 double        ev,
                 double        rate,
                 double        rate_factor,
                 double        stretch,
                 double       *sig,
                 double       *st) const;

    /// The constants of the built-in DIF curves for one f'c (powers of f'c computed once).
    struct DifCurves
    {
      /// Compression: DIF = (rate / 30e-6)^compression_exponent up to 30 1/s (1.026 alpha).
      double compression_exponent;
      /// Compression above 30 1/s: DIF = compression_factor (rate / 30e-6)^(1/3) (10^(6.156 alpha - 2)).
      double compression_factor;
      /// Tension: DIF = (rate / 1e-6)^tension_exponent up to 1 1/s (delta).
      double tension_exponent;
      /// Tension above 1 1/s: DIF = tension_factor (rate / 1e-6)^(1/3) (10^(6 delta - 2)).
      double tension_factor;
    };

    /// The constants of default_dif() for compressive strength @p fc (Pa).
    static DifCurves
    default_dif_curves(double fc);

    /// default_dif() with the constants computed.
    static double
    default_dif(const DifCurves &curves, double rate, bool tension);

    /// Text keys: "auto" or a value.
    struct Keys
    {
      std::string tensile_strength = "auto";
      std::string a0 = "auto", a1 = "auto", a2 = "auto";
      std::string a0y = "auto", a1y = "auto", a2y = "auto";
      std::string a1f = "auto", a2f = "auto";
      std::string b1 = "auto", b2 = "auto", b3 = "auto";
      std::string omega = "auto";
      std::string damage_table = "auto";
      std::string eos_table = "auto";
      std::string shear_modulus = "auto";
      std::string dif_c = "default";
      std::string dif_t = "default";
    };

    /// Builds the input parameter set from the keys (NaN/empty for `auto`); throws
    /// std::invalid_argument with the key name and reason on a malformed key.
    KccParameters
    input_parameters() const;

    /// Builds eos_ and the DIF tables from par_.
    void
    build_derived();

    KccParameters par_;
    Keys          keys_;
    CompactionEos eos_;
    DifCurves     dif_curves_{};
    StrengthField field_;
  };
} // namespace shard::materials
