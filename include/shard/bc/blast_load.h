// SPDX-License-Identifier: LGPL-2.1-or-later
/**
 * @file blast_load.h
 * @brief Empirical blast load: Kingery-Bulmash (KB) blast-wave parameters of a TNT charge, the
 *        modified Friedlander pressure history and the angle-of-incidence interpolation.
 *        Used by the `blast` boundary condition (`I - Boundary conditions`); theory, sources and
 *        validation in doc/manual/blast.md.
 * @ingroup bc
 *
 * Sources of the fits: Kingery & Bulmash (1984), ARBRL-TR-02555, in the CONWEP form of
 * Randers-Pehrson & Bannister (1997), ARL-TR-1310 (imperial units, common logarithms); the
 * coefficients and the two resolved transcription errors are listed in doc/manual/blast.md.
 */
#pragma once

#include <array>
#include <string>

namespace shard::bc
{
  /// Kind of burst: which Kingery-Bulmash fit set applies.
  enum class Burst
  {
    /// Charge on the ground: hemispherical surface burst (UFC 3-340-02 Fig. 2-15).
    hemispherical,
    /// Charge in free air, far from any surface: spherical free-air burst (UFC 3-340-02 Fig. 2-7).
    spherical
  };

  /// Parses "hemispherical" or "spherical"; throws std::invalid_argument otherwise.
  Burst
  parse_burst(const std::string &text);

  /// Smallest scaled distance of the KB fits: 0.17 ft/lb^(1/3) hemispherical, 0.134 spherical, in m/kg^(1/3).
  double
  kb_z_min(Burst burst);

  /// Largest scaled distance of the KB fits: 100 ft/lb^(1/3) = 39.67 m/kg^(1/3) for both.
  double
  kb_z_max(Burst burst);

  /**
   * @brief Blast-wave parameters at one point, in SI units for a given charge.
   * Pressures are overpressures above ambient.
   */
  struct BlastWave
  {
    /// Peak incident (side-on) overpressure Pso (Pa).
    double pso = 0;
    /// Peak normally reflected overpressure Pr (Pa).
    double pr = 0;
    /// Incident positive-phase impulse is (Pa s).
    double is = 0;
    /// Normally reflected positive-phase impulse ir (Pa s).
    double ir = 0;
    /// Arrival time of the shock front ta (s).
    double ta = 0;
    /// Positive-phase duration t0 (s).
    double t0 = 0;
  };

  /**
   * @brief Kingery-Bulmash parameters at scaled distance @p z (m/kg^(1/3), Z = R / W^(1/3)) for a
   * TNT mass @p w (kg).
   *
   * Each quantity is 10^Y, Y = sum_i C_i U^i, U = K0 + K1 log10(Z) with Z in ft/lb^(1/3); the scaled
   * impulses and times are multiplied by W^(1/3) (W in lb). Below the first segment of the
   * duration fit (0.45 ft/lb^(1/3) hemispherical, 0.37 spherical) t0 is held at its value there,
   * as the ARL-TR-1310 code does.
   *
   * Throws std::domain_error when @p z is outside [kb_z_min(), kb_z_max()] or @p w <= 0: the
   * polynomials are not valid there and diverge a little outside.
   */
  BlastWave
  kingery_bulmash(double z, double w, Burst burst);

  /**
   * @brief i / (P t0) of the modified Friedlander pulse P (1 - s) exp(-b s), s = tau / t0 in [0, 1]:
   * 1/b - (1 - exp(-b)) / b^2 (series 1/2 - b/6 + b^2/24 - ... for small b).
   */
  double
  friedlander_impulse_ratio(double b);

  /**
   * @brief One positive phase p(tau) = peak (1 - tau / duration) exp(-decay tau / duration) for
   * 0 <= tau <= duration, zero otherwise (the negative phase is not modelled).
   */
  struct Friedlander
  {
    /// Peak overpressure (Pa).
    double peak = 0;
    /// Positive-phase duration (s).
    double duration = 0;
    /// Decay coefficient b (1).
    double decay = 0;
    /// True when the impulse could not be matched with the KB duration (see from_impulse()).
    bool lengthened = false;

    /// Overpressure at @p tau after arrival (Pa).
    double
    pressure(double tau) const;

    /// Closed-form impulse of the positive phase, peak duration friedlander_impulse_ratio(decay) (Pa s).
    double
    impulse() const;

    /**
     * @brief The pulse with peak @p p, duration @p t0 and the decay b that gives impulse @p i.
     *
     * A solution b >= 0 exists only when k = p t0 / i > 2 (a triangle, b = 0, already carries
     * p t0 / 2, the most a pulse of that peak and duration can). Otherwise (KB gives k < 2 for the
     * spherical burst beyond about 39 m/kg^(1/3)) the fallback is the triangle b = 0 with the
     * duration lengthened to 2 i / p, which keeps peak and impulse; @c lengthened is then true.
     * b is found by bisection on the monotone friedlander_impulse_ratio() to 1e-13 relative.
     */
    static Friedlander
    from_impulse(double p, double i, double t0);
  };

  /**
   * @brief Pressure on a face whose outward normal makes the angle theta with the direction to
   * the charge: Pr cos^2(theta) + Pso (1 + cos(theta) - 2 cos^2(theta)) for cos(theta) > 0, Pso for
   * faces turned away (Randers-Pehrson & Bannister 1997, ARL-TR-1310; the CONWEP form).
   * It gives Pr at normal incidence and Pso at grazing incidence, and ignores the Mach-stem
   * peak of the reflection coefficient near 40 degrees.
   */
  double
  oblique_pressure(double p_incident, double p_reflected, double cos_theta);

  /**
   * @brief The load history at one point of a loaded surface: incident and reflected pulses, arrival
   * time and angle of incidence, evaluated once; pressure() is then cheap.
   */
  struct BlastPoint
  {
    /// KB parameters at the point.
    BlastWave wave;
    /// Scaled distance of the point (m/kg^(1/3)).
    double z = 0;
    /// Cosine of the angle between the face normal and the direction to the charge.
    double cos_theta = 0;
    /// Incident (side-on) pulse: Pso, t0 and the decay from is.
    Friedlander incident;
    /// Normally reflected pulse: Pr, t0 and the decay from ir.
    Friedlander reflected;

    /// Overpressure at time @p t after detonation (Pa): oblique_pressure() of the two pulses at t - ta.
    double
    pressure(double t) const;
  };

  /**
   * @brief A charge: TNT-equivalent mass, centre and burst type.
   */
  class BlastCharge
  {
  public:
    /**
     * @param tnt_mass TNT-equivalent mass W (kg), > 0
     * @param centre charge centre (m); for a surface burst the point of the ground under the charge centre
     * @param burst fit set
     */
    BlastCharge(double tnt_mass, const std::array<double, 3> &centre, Burst burst);

    /// Scaled distance of @p x from the charge, |x - centre| / W^(1/3) (m/kg^(1/3)).
    double
    scaled_distance(const std::array<double, 3> &x) const;

    /**
     * @brief The load history at @p x on a face with outward unit normal @p n.
     * Throws std::domain_error when the scaled distance of @p x is outside the KB range.
     */
    BlastPoint
    at(const std::array<double, 3> &x, const std::array<double, 3> &n) const;

    /// TNT-equivalent mass (kg).
    double
    mass() const
    {
      return w_;
    }


  private:
    double                w_;
    std::array<double, 3> centre_;
    Burst                 burst_;
  };
} // namespace shard::bc
