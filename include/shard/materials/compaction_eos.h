// SPDX-License-Identifier: LGPL-2.1-or-later
/**
 * @file compaction_eos.h
 * @brief Tabulated compaction equation of state (the behaviour of LS-DYNA's EOS 8 with
 *        zero temperature terms), used by the K&C concrete model.
 * @ingroup materials
 *
 * Theory: doc/materials/kcc.md, section "Equation of state"; design/materials.md section 4.
 */
#pragma once

#include <string>
#include <vector>

namespace shard::materials
{
  /**
   * @brief Pressure as a function of the compaction x = -(ln J - eps_v^p) and its history
   * maximum x_max.
   *
   * The table holds rows (eps_v, p, K) with eps_v = ln(V/V0) <= 0 strictly decreasing from 0,
   * the loading pressure p non-decreasing from 0 and the unloading bulk modulus K > 0.
   * With x_i = -eps_v,i and C(x), K(x) the piecewise-linear interpolants:
   *
   *     x >= x_max:  p = C(x)                                  (virgin loading, x_max <- x)
   *     x <  x_max:  p = C(x_max) - K(x_max) (x_max - x)        (unloading and reloading)
   *
   * Beyond the last row C continues with the slope of its last segment and K stays at its
   * last value; below x = 0 (expansion) the unloading line continues into tension, the model
   * that owns the EOS limits the tension. Compaction is permanent: unloading to p = 0 from
   * x_max leaves x = x_max - C(x_max)/K(x_max).
   */
  class CompactionEos
  {
  public:
    /// Result of one evaluation.
    struct State
    {
      /// Pressure, compression positive (Pa).
      double pressure;
      /// Updated history maximum of x (1).
      double max_compaction;
      /// Unloading bulk modulus K(x_max) at the updated x_max (Pa).
      double unloading_modulus;
      /// Stiffness for the wave speed: max(K(x_max), dC/dx at x when loading) (Pa).
      double wave_modulus;
    };

    /**
     * @brief Sets the table.
     * @param strain Volumetric strains ln(V/V0), first 0, strictly decreasing.
     * @param pressure Loading pressures (Pa), first 0, non-decreasing.
     * @param modulus Unloading bulk moduli (Pa), > 0.
     * Checks are the caller's (KccConcrete::check_parameters names the key).
     */
    void
    set_table(const std::vector<double> &strain,
              const std::vector<double> &pressure,
              const std::vector<double> &modulus);

    /**
     * @brief Evaluates the EOS.
     * @param compaction x = -(ln J - eps_v^p), compression positive (1).
     * @param max_compaction History maximum of x before this evaluation (>= 0).
     */
    State
    evaluate(double compaction, double max_compaction) const;

    /// The pressure of evaluate() alone (bitwise the same), for root searches (Pa).
    double
    pressure(double compaction, double max_compaction) const;

    /// Loading curve C(x) (Pa), continued with the last slope beyond the table.
    double
    loading_pressure(double compaction) const;

    /// Unloading modulus K(x) (Pa), linear between rows, constant beyond them.
    double
    unloading_modulus(double compaction) const;

    /**
     * @brief The compaction at which the unloading line from @p max_compaction reaches
     * pressure @p target (used for the tension cutoff): x_max - (C(x_max) - target)/K(x_max).
     */
    double
    compaction_at_pressure(double target, double max_compaction) const;

    /// Compactions x_i of the table rows (1).
    const std::vector<double> &
    compactions() const
    {
      return x_;
    }

    /// Loading pressures of the table rows (Pa).
    const std::vector<double> &
    pressures() const
    {
      return p_;
    }

    /// Unloading moduli of the table rows (Pa).
    const std::vector<double> &
    moduli() const
    {
      return k_;
    }

  private:
    /// Segment k with x_k <= x < x_{k+1} (0 below the table, last-1 above).
    unsigned int
    segment(double compaction) const;

    /// unloading_modulus() with the segment of @p compaction already known.
    double
    modulus_in_segment(unsigned int k, double compaction) const;

    std::vector<double> x_;
    std::vector<double> p_;
    std::vector<double> k_;
    std::vector<double> slope_;
  };
} // namespace shard::materials
