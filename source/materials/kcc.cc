// SPDX-License-Identifier: LGPL-2.1-or-later
/**
 * @file kcc.cc
 * @brief K&C concrete (Release III): surfaces, damage, rate enhancement, parameter
 *        generation and the stress update (design/materials.md sections 1-8,
 *        decisions in doc/materials/kcc.md).
 */
#include <shard/materials/elastic.h>
#include <shard/materials/kcc.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <map>
#include <ostream>
#include <sstream>
#include <stdexcept>

namespace shard::materials
{
  namespace
  {
    constexpr double nan_value = std::numeric_limits<double>::quiet_NaN();

    /// Biaxial strength ratio alpha: equal-biaxial compression peaks at alpha f'c.
    constexpr double biaxial_ratio = 1.15;
    /// Floor of the base (1 + p/(r_f f't)) of the damage increment (design 3.1, open point 9).
    constexpr double damage_base_floor = 1e-2;
    /// Largest elastic stress increment M0 e of one tensile sub-increment, as a fraction of f't.
    constexpr double max_tension_increment = 0.1;
    /// Most sub-increments of one step (a step of 128 x 0.1 f't = 12.8 f't is resolved).
    constexpr unsigned int max_tension_substeps = 128;

    /// The 50 MPa EOS 8 table of Yin et al. (2023): eps_v, p (MPa), K (GPa).
    constexpr double eos50[10][3] = {{0., 0., 12.38},
                                     {-0.0015, 18.57, 12.38},
                                     {-0.0043, 40.48, 12.55},
                                     {-0.0101, 64.99, 13.18},
                                     {-0.0305, 123.48, 15.68},
                                     {-0.0513, 186.25, 18.20},
                                     {-0.0726, 264.24, 20.70},
                                     {-0.0943, 404.25, 22.59},
                                     {-0.174, 2360.1, 50.83},
                                     {-0.208, 3609.8, 61.90}};

    /// The generic Release III damage table (lambda, eta).
    constexpr double damage13[13][2] = {{0., 0.},      {8e-6, 0.85},   {2.4e-5, 0.97}, {4e-5, 0.99},
                                        {5.6e-5, 1.},  {7.2e-5, 0.99}, {8.8e-5, 0.97}, {3.2e-4, 0.5},
                                        {5.2e-4, 0.1}, {5.7e-4, 0.},   {1., 0.},       {10., 0.},
                                        {1e10, 0.}};

    /// Parses "auto" (NaN) or a number; throws std::invalid_argument naming @p key.
    double
    auto_or_number(const std::string &text, const std::string &key)
    {
      const std::string t = base::trim(text);
      if (t == "auto")
        return nan_value;
      std::size_t used = 0;
      double      value;
      try
        {
          value = std::stod(t, &used);
        }
      catch (const std::exception &)
        {
          throw std::invalid_argument(key + "|must be 'auto' or a number");
        }
      if (used != t.size() || !std::isfinite(value))
        throw std::invalid_argument(key + "|must be 'auto' or a finite number");
      return value;
    }

    /// Root of a decreasing-then-negative function on [0, hi] by bisection (to round-off).
    template <class F>
    double
    bisect(const F &f, double lo, double hi)
    {
      for (unsigned int it = 0; it < 200 && hi - lo > 1e-15 * hi; ++it)
        {
          const double mid = 0.5 * (lo + hi);
          (f(mid) > 0. ? lo : hi) = mid;
        }
      return 0.5 * (lo + hi);
    }

    /// Linear interpolation in a table, constant beyond the ends.
    double
    interpolate(const std::vector<double> &x, const std::vector<double> &y, const double v)
    {
      if (v <= x.front())
        return y.front();
      if (v >= x.back())
        return y.back();
      const auto         it = std::upper_bound(x.begin(), x.end(), v);
      const std::size_t  k  = static_cast<std::size_t>(it - x.begin()) - 1;
      const double       w  = (v - x[k]) / (x[k + 1] - x[k]);
      return y[k] + w * (y[k + 1] - y[k]);
    }

    /// Writes "a b; c d; ..." with full precision.
    std::string
    table_text(const std::vector<const std::vector<double> *> &columns)
    {
      std::ostringstream out;
      out.precision(10);
      const std::size_t n = columns.front()->size();
      for (std::size_t i = 0; i < n; ++i)
        {
          if (i > 0)
            out << "; ";
          for (std::size_t c = 0; c < columns.size(); ++c)
            out << (c > 0 ? " " : "") << (*columns[c])[i];
        }
      return out.str();
    }
  } // namespace

  // --------------------------------------------------------------------------------------
  // Parameters
  // --------------------------------------------------------------------------------------

  std::string
  KccConcrete::model_name() const
  {
    return "kcc";
  }

  void
  KccConcrete::declare_parameters(dealii::ParameterHandler &prm)
  {
    using dealii::Patterns::Anything;
    using dealii::Patterns::Bool;
    using dealii::Patterns::Double;
    prm.add_parameter("density", par_.density,
                      "Mass density of the concrete. Unit: kg/m^3. Range: > 0.", Double());
    prm.add_parameter("poisson's ratio", par_.poissons_ratio,
                      "Poisson's ratio; with the EOS unloading bulk modulus K it gives the shear "
                      "modulus G = 3K(1-2nu)/(2(1+nu)). Unit: 1. Range: 0 <= nu < 0.5.", Double());
    prm.add_parameter("compressive strength", par_.compressive_strength,
                      "Unconfined compressive strength f'c (positive). Every key set to 'auto' is "
                      "generated from it (doc/materials/kcc.md). Unit: Pa. Range: 1e6 to 300e6.",
                      Double());
    const auto generated = [&](const char *key, std::string &member, const std::string &doc) {
      prm.add_parameter(key, member, "'auto' (generated from f'c) or a value. " + doc, Anything());
    };
    generated("tensile strength", keys_.tensile_strength,
              "Uniaxial tensile strength f't; generated f't = 0.3007 (f'c/MPa)^(2/3) MPa. "
              "Unit: Pa. Range: > 0.");
    generated("a0", keys_.a0, "Maximum surface a0 + p/(a1 + a2 p); generated 0.29559 f'c. "
                              "Unit: Pa. Range: > 0.");
    generated("a1", keys_.a1, "Maximum surface a1; generated 0.4463. Unit: 1. Range: > 0.");
    generated("a2", keys_.a2, "Maximum surface a2; generated 0.08081/f'c. Unit: 1/Pa. Range: >= 0.");
    generated("a0y", keys_.a0y, "Yield surface a0y + p/(a1y + a2y p); generated 0.22313 f'c. "
                                "Unit: Pa. Range: > 0.");
    generated("a1y", keys_.a1y, "Yield surface a1y; generated 0.625. Unit: 1. Range: > 0.");
    generated("a2y", keys_.a2y, "Yield surface a2y; generated 0.25769/f'c. Unit: 1/Pa. Range: >= 0.");
    generated("a1f", keys_.a1f, "Residual surface p/(a1f + a2f p); generated 0.4417. Unit: 1. "
                                "Range: > 1/3 (the residual surface must lie below q = 3p).");
    generated("a2f", keys_.a2f, "Residual surface a2f; generated 0.11840/f'c. Unit: 1/Pa. Range: >= 0.");
    generated("b1", keys_.b1, "Damage exponent in compression: d lambda = d eps_p / (r_f (1 + "
                              "p/(r_f f't))^b1) for p >= 0; generated 1.6. Unit: 1. Range: >= 0.");
    generated("b2", keys_.b2, "Damage exponent in tension (p < 0); generated 1.35. Unit: 1. "
                              "Range: >= 0.");
    generated("b3", keys_.b3, "Volumetric damage in hydrostatic tension: d lambda = b3 d eps_v^crack "
                              "/ r_f; generated 1.15. Unit: 1. Range: >= 0.");
    generated("omega", keys_.omega, "Associativity: plastic volume change omega dY/dp d eps_p "
                                    "(0 none, 1 associative); generated 0.5. Unit: 1. Range: 0 to 1.");
    prm.add_parameter("edrop", par_.edrop,
                      "Post-peak decay of the associativity: omega_eff = omega eta^edrop after the "
                      "peak (0 keeps omega). Unit: 1. Range: >= 0.", Double());
    generated("damage table", keys_.damage_table,
              "Rows 'lambda eta' separated by ';' (the 13 pairs of Release III); generated: the "
              "generic table 0 0; 8e-6 0.85; 2.4e-5 0.97; 4e-5 0.99; 5.6e-5 1; 7.2e-5 0.99; 8.8e-5 "
              "0.97; 3.2e-4 0.5; 5.2e-4 0.1; 5.7e-4 0; 1 0; 10 0; 1e10 0. lambda_m is the first "
              "lambda with eta = 1. Unit: 1 and 1. Range: first row 0 0, lambda strictly increasing, "
              "0 <= eta <= 1, largest eta exactly 1.");
    generated("eos table", keys_.eos_table,
              "Tabulated compaction EOS, rows 'ln(V/V0)  pressure  unloading bulk modulus' separated by "
              "';'; generated: the 50 MPa table of Yin et al. (2023) with pressures and moduli scaled by "
              "(f'c/50 MPa)^0.638. Unit: 1, Pa, Pa. Range: at least 2 rows, first row 0 0 K, strains "
              "strictly decreasing, pressures non-decreasing, moduli > 0.");
    generated("shear modulus", keys_.shear_modulus,
              "'auto': G = 3K(1-2nu)/(2(1+nu)) from the current EOS unloading modulus K; a value fixes "
              "G. Unit: Pa. Range: > 0.");
    prm.add_parameter("rate effects", par_.rate_effects,
                      "Radial strain-rate enhancement of all surfaces by the dynamic increase factor "
                      "r_f of the effective strain rate sqrt(2/3 D:D). Switch off for quasi-static "
                      "tests.", Bool());
    prm.add_parameter("compression DIF", keys_.dif_c,
                      "'default' (CEB-FIP MC90 curve of f'c) or rows 'strain rate  DIF' separated by ';', "
                      "interpolated linearly in log10(rate), constant beyond the ends; used when p >= 0. "
                      "Unit: 1/s and 1. Range: rates > 0 strictly increasing, DIF >= 1.", Anything());
    prm.add_parameter("tension DIF", keys_.dif_t,
                      "'default' (Malvar & Ross 1998 curve of f'c) or rows 'strain rate  DIF'; used when "
                      "p < 0. Unit: 1/s and 1. Range: as compression DIF.", Anything());
    prm.add_parameter("compression DIF cap", par_.dif_c_cap,
                      "Upper bound of the compression DIF (0: none). Unit: 1. Range: 0 or >= 1.", Double());
    prm.add_parameter("tension DIF cap", par_.dif_t_cap,
                      "Upper bound of the tension DIF (0: none). Unit: 1. Range: 0 or >= 1.", Double());
    prm.add_parameter("localization width", par_.localization_width,
                      "Size regularization of softening (LOCWIDTH-like): the post-peak lambda abscissae "
                      "of the damage table are stretched by w/h, h the element or particle size, so the "
                      "energy per crack area stays that of a band of width w. 0: no regularization. "
                      "Unit: m. Range: >= 0.", Double());
    prm.add_parameter("failure scaled damage", par_.failure_scaled_damage,
                      "Scaled damage delta at which the slot 'failed' becomes 1 (an indicator; the "
                      "stress keeps following the residual surface). 0: never. Unit: 1. Range: 0, or "
                      "1 to 2.", Double());
    prm.add_parameter("strength modulus", par_.strength_modulus,
                      "Weibull modulus m of a random strength field (the flaws, doc/materials/kcc.md decision "
                      "13): every surface of a point is scaled by a factor s of mean 1 (coefficient of "
                      "variation 0.149 for m = 8), constant on the cells of a grid of size 'strength cell "
                      "size' fixed in the reference configuration, so that a uniformly stretched body breaks "
                      "at its weak places first. 0: uniform strength. Unit: 1. Range: 0, or 2 to 100.",
                      Double());
    prm.add_parameter("strength cell size", par_.strength_cell_size,
                      "Size l of the cells of the strength field (the flaw spacing; independent of the mesh "
                      "and particle spacing). Unit: m. Range: > 0.", Double());
    prm.add_parameter("strength seed", par_.strength_seed,
                      "Selects the realization of the strength field (the same on every rank and after a "
                      "restart). Unit: 1. Range: >= 0.", dealii::Patterns::Integer(0));
  }

  KccParameters
  KccConcrete::input_parameters() const
  {
    KccParameters in = par_;
    in.tensile_strength = auto_or_number(keys_.tensile_strength, "tensile strength");
    in.a0               = auto_or_number(keys_.a0, "a0");
    in.a1               = auto_or_number(keys_.a1, "a1");
    in.a2               = auto_or_number(keys_.a2, "a2");
    in.a0y              = auto_or_number(keys_.a0y, "a0y");
    in.a1y              = auto_or_number(keys_.a1y, "a1y");
    in.a2y              = auto_or_number(keys_.a2y, "a2y");
    in.a1f              = auto_or_number(keys_.a1f, "a1f");
    in.a2f              = auto_or_number(keys_.a2f, "a2f");
    in.b1               = auto_or_number(keys_.b1, "b1");
    in.b2               = auto_or_number(keys_.b2, "b2");
    in.b3               = auto_or_number(keys_.b3, "b3");
    in.omega            = auto_or_number(keys_.omega, "omega");
    const double g      = auto_or_number(keys_.shear_modulus, "shear modulus");
    in.shear_modulus    = std::isnan(g) ? 0. : (g > 0. ? g : -1.);

    const auto table = [](const std::string &text, const std::string &key, unsigned int columns) {
      try
        {
          return base::parse_table(text, columns);
        }
      catch (const std::invalid_argument &e)
        {
          throw std::invalid_argument(key + "|must be rows of " + std::to_string(columns) +
                                      " numbers separated by ';' (" + e.what() + ")");
        }
    };
    in.lambda.clear();
    in.eta.clear();
    if (base::trim(keys_.damage_table) != "auto")
      for (const auto &row : table(keys_.damage_table, "damage table", 2))
        {
          in.lambda.push_back(row[0]);
          in.eta.push_back(row[1]);
        }
    in.eos_strain.clear();
    in.eos_pressure.clear();
    in.eos_modulus.clear();
    if (base::trim(keys_.eos_table) != "auto")
      for (const auto &row : table(keys_.eos_table, "eos table", 3))
        {
          in.eos_strain.push_back(row[0]);
          in.eos_pressure.push_back(row[1]);
          in.eos_modulus.push_back(row[2]);
        }
    in.dif_c_rate.clear();
    in.dif_c.clear();
    in.dif_t_rate.clear();
    in.dif_t.clear();
    if (base::trim(keys_.dif_c) != "default")
      for (const auto &row : table(keys_.dif_c, "compression DIF", 2))
        {
          in.dif_c_rate.push_back(row[0]);
          in.dif_c.push_back(row[1]);
        }
    if (base::trim(keys_.dif_t) != "default")
      for (const auto &row : table(keys_.dif_t, "tension DIF", 2))
        {
          in.dif_t_rate.push_back(row[0]);
          in.dif_t.push_back(row[1]);
        }
    return in;
  }

  void
  KccConcrete::check_parameters(const base::PrmSource &source, const std::string &path) const
  {
    using internal::number_to_string;
    const auto fail = [&](const std::string &key, const std::string &value, const std::string &why) {
      source.fail(path + "/" + key, value, why);
    };
    const KccParameters &p = par_;
    if (!(p.density > 0.) || !std::isfinite(p.density))
      fail("density", number_to_string(p.density), "must be > 0. Unit: kg/m^3");
    if (!(p.poissons_ratio >= 0. && p.poissons_ratio < 0.5))
      fail("poisson's ratio", number_to_string(p.poissons_ratio), "must satisfy 0 <= nu < 0.5. Unit: 1");
    if (!(p.compressive_strength >= 1e6 && p.compressive_strength <= 300e6))
      fail("compressive strength", number_to_string(p.compressive_strength),
           "must lie in [1e6, 300e6] (the unit is Pa: 48 MPa is 48e6)");

    KccParameters in;
    try
      {
        in = input_parameters();
      }
    catch (const std::invalid_argument &e)
      {
        const std::string what = e.what();
        const auto        bar  = what.find('|');
        const std::string key  = what.substr(0, bar);
        const std::map<std::string, const std::string *> texts = {
          {"tensile strength", &keys_.tensile_strength}, {"a0", &keys_.a0}, {"a1", &keys_.a1},
          {"a2", &keys_.a2}, {"a0y", &keys_.a0y}, {"a1y", &keys_.a1y}, {"a2y", &keys_.a2y},
          {"a1f", &keys_.a1f}, {"a2f", &keys_.a2f}, {"b1", &keys_.b1}, {"b2", &keys_.b2},
          {"b3", &keys_.b3}, {"omega", &keys_.omega}, {"shear modulus", &keys_.shear_modulus},
          {"damage table", &keys_.damage_table}, {"eos table", &keys_.eos_table},
          {"compression DIF", &keys_.dif_c}, {"tension DIF", &keys_.dif_t}};
        fail(key, texts.count(key) ? *texts.at(key) : "", what.substr(bar + 1));
      }

    const auto positive = [&](const char *key, const double v, const char *unit) {
      if (!std::isnan(v) && !(v > 0.))
        fail(key, number_to_string(v), std::string("must be > 0 (or 'auto'). Unit: ") + unit);
    };
    const auto non_negative = [&](const char *key, const double v, const char *unit) {
      if (!std::isnan(v) && !(v >= 0.))
        fail(key, number_to_string(v), std::string("must be >= 0 (or 'auto'). Unit: ") + unit);
    };
    positive("tensile strength", in.tensile_strength, "Pa");
    positive("a0", in.a0, "Pa");
    positive("a1", in.a1, "1");
    non_negative("a2", in.a2, "1/Pa");
    positive("a0y", in.a0y, "Pa");
    positive("a1y", in.a1y, "1");
    non_negative("a2y", in.a2y, "1/Pa");
    if (!std::isnan(in.a1f) && !(in.a1f > 1. / 3.))
      fail("a1f", keys_.a1f, "must be > 1/3 (the residual surface must lie below q = 3p) or 'auto'. Unit: 1");
    non_negative("a2f", in.a2f, "1/Pa");
    non_negative("b1", in.b1, "1");
    non_negative("b2", in.b2, "1");
    non_negative("b3", in.b3, "1");
    if (!std::isnan(in.omega) && !(in.omega >= 0. && in.omega <= 1.))
      fail("omega", keys_.omega, "must lie in [0, 1] or be 'auto'. Unit: 1");
    if (in.shear_modulus < 0.)
      fail("shear modulus", keys_.shear_modulus, "must be > 0 or 'auto'. Unit: Pa");
    if (!(p.edrop >= 0.))
      fail("edrop", number_to_string(p.edrop), "must be >= 0. Unit: 1");
    if (!(p.strength_modulus == 0. || (p.strength_modulus >= 2. && p.strength_modulus <= 100.)))
      fail("strength modulus", number_to_string(p.strength_modulus),
           "must be 0 (uniform strength) or lie in [2, 100]. Unit: 1");
    if (!(p.strength_cell_size > 0.) || !std::isfinite(p.strength_cell_size))
      fail("strength cell size", number_to_string(p.strength_cell_size), "must be > 0. Unit: m");

    if (!in.lambda.empty())
      {
        const std::string &t = keys_.damage_table;
        if (in.lambda.size() < 2)
          fail("damage table", t, "must have at least 2 rows");
        if (in.lambda[0] != 0. || in.eta[0] != 0.)
          fail("damage table", t, "must start with the row '0 0'");
        double max_eta = 0.;
        for (std::size_t i = 0; i < in.lambda.size(); ++i)
          {
            if (i > 0 && !(in.lambda[i] > in.lambda[i - 1]))
              fail("damage table", t, "lambda must be strictly increasing (row " + std::to_string(i + 1) + ")");
            if (!(in.eta[i] >= 0. && in.eta[i] <= 1.))
              fail("damage table", t, "eta must lie in [0, 1] (row " + std::to_string(i + 1) + ")");
            max_eta = std::max(max_eta, in.eta[i]);
          }
        if (max_eta != 1.)
          fail("damage table", t, "must reach eta = 1 exactly (the peak, lambda_m)");
      }
    if (!in.eos_strain.empty())
      {
        const std::string &t = keys_.eos_table;
        if (in.eos_strain.size() < 2)
          fail("eos table", t, "must have at least 2 rows");
        if (in.eos_strain[0] != 0. || in.eos_pressure[0] != 0.)
          fail("eos table", t, "must start with a row '0 0 K' (no strain, no pressure)");
        for (std::size_t i = 0; i < in.eos_strain.size(); ++i)
          {
            if (!(in.eos_modulus[i] > 0.))
              fail("eos table", t, "unloading modulus must be > 0 Pa (row " + std::to_string(i + 1) + ")");
            if (i == 0)
              continue;
            if (!(in.eos_strain[i] < in.eos_strain[i - 1]))
              fail("eos table", t, "strains ln(V/V0) must be strictly decreasing (row " +
                                     std::to_string(i + 1) + ")");
            if (!(in.eos_pressure[i] >= in.eos_pressure[i - 1]))
              fail("eos table", t, "pressures must not decrease (row " + std::to_string(i + 1) + ")");
          }
      }
    const auto check_dif = [&](const char *key, const std::string &t, const std::vector<double> &rate,
                               const std::vector<double> &dif) {
      for (std::size_t i = 0; i < rate.size(); ++i)
        {
          if (!(rate[i] > 0.) || (i > 0 && !(rate[i] > rate[i - 1])))
            fail(key, t, "rates must be > 0 and strictly increasing (row " + std::to_string(i + 1) + ")");
          if (!(dif[i] >= 1.))
            fail(key, t, "DIF must be >= 1 (row " + std::to_string(i + 1) + ")");
        }
    };
    check_dif("compression DIF", keys_.dif_c, in.dif_c_rate, in.dif_c);
    check_dif("tension DIF", keys_.dif_t, in.dif_t_rate, in.dif_t);
    if (!(p.dif_c_cap == 0. || p.dif_c_cap >= 1.))
      fail("compression DIF cap", number_to_string(p.dif_c_cap), "must be 0 (none) or >= 1. Unit: 1");
    if (!(p.dif_t_cap == 0. || p.dif_t_cap >= 1.))
      fail("tension DIF cap", number_to_string(p.dif_t_cap), "must be 0 (none) or >= 1. Unit: 1");
    if (!(p.localization_width >= 0.))
      fail("localization width", number_to_string(p.localization_width), "must be >= 0. Unit: m");
    if (!(p.failure_scaled_damage == 0. ||
          (p.failure_scaled_damage >= 1. && p.failure_scaled_damage <= 2.)))
      fail("failure scaled damage", number_to_string(p.failure_scaled_damage),
           "must be 0 (never) or lie in [1, 2]. Unit: 1");

    try
      {
        resolve(in);
      }
    catch (const std::invalid_argument &e)
      {
        fail("a0", keys_.a0, e.what());
      }
  }

  KccParameters
  KccConcrete::resolve(KccParameters in)
  {
    const double fc  = in.compressive_strength;
    const double fcm = fc * 1e-6; // f'c in MPa
    const auto   pick = [](double &v, const double generated) {
      if (std::isnan(v))
        v = generated;
    };
    pick(in.tensile_strength, 0.3007 * std::pow(fcm, 2. / 3.) * 1e6);
    pick(in.a0, 0.29559 * fc);
    pick(in.a1, 0.4463);
    pick(in.a2, 0.08081 / fc);
    pick(in.a0y, 0.22313 * fc);
    pick(in.a1y, 0.625);
    pick(in.a2y, 0.25769 / fc);
    pick(in.a1f, 0.4417);
    pick(in.a2f, 0.11840 / fc);
    pick(in.b1, 1.6);
    pick(in.b2, 1.35);
    pick(in.b3, 1.15);
    pick(in.omega, 0.5);
    if (in.lambda.empty())
      for (const auto &row : damage13)
        {
          in.lambda.push_back(row[0]);
          in.eta.push_back(row[1]);
        }
    if (in.eos_strain.empty())
      {
        const double scale = std::pow(fcm / 50., 0.638);
        for (const auto &row : eos50)
          {
            in.eos_strain.push_back(row[0]);
            in.eos_pressure.push_back(row[1] * 1e6 * scale);
            in.eos_modulus.push_back(row[2] * 1e9 * scale);
          }
      }

    // f'c and f'yc where the rational branches pass through unconfined compression,
    // Delta sigma(f/3) = f: the low-pressure branches are built on them, so the surfaces are
    // continuous whatever a0..a2 the user gives.
    const auto solve_uc = [](const double a0, const double a1, const double a2, const char *name) {
      const auto   h  = [&](const double f) { return a0 + (f / 3.) / (a1 + a2 * f / 3.) - f; };
      const double hi = a2 > 0. ? 2. * (a0 + 1. / a2) : (a1 < 1. / 3. ? 0. : 10. * a0 / (1. - 1. / (3. * a1)));
      if (!(hi > 0.) || !(h(hi) < 0.))
        throw std::invalid_argument(std::string("the ") + name +
                                    " surface never meets unconfined compression q = 3p "
                                    "(needs a1 > 1/3 when a2 = 0)");
      return bisect(h, 0., hi);
    };
    in.fc  = solve_uc(in.a0, in.a1, in.a2, "maximum");
    in.fyc = solve_uc(in.a0y, in.a1y, in.a2y, "yield");
    if (!(in.fyc < in.fc))
      throw std::invalid_argument("the yield surface must lie below the maximum surface at unconfined "
                                  "compression (f'yc < f'c)");
    in.psi_uc = 0.5 + 1.5 * in.tensile_strength / in.fc;
    const double pb = 2. * biaxial_ratio * in.fc / 3.;
    in.psi_bc = biaxial_ratio * in.fc / (in.a0 + pb / (in.a1 + in.a2 * pb));
    if (!(in.psi_uc > 0.5 && in.psi_uc < 1.) || !(in.psi_bc > 0.5 && in.psi_bc <= 1.))
      throw std::invalid_argument("psi at unconfined or equal-biaxial compression lies outside (0.5, 1]: "
                                  "f't / f'c too large for the surfaces");
    in.lambda_m = 0.;
    for (std::size_t i = 0; i < in.eta.size(); ++i)
      if (in.eta[i] == 1.)
        {
          in.lambda_m = in.lambda[i];
          break;
        }
    return in;
  }

  void
  KccConcrete::prepare()
  {
    par_ = resolve(input_parameters());
    build_derived();
  }

  void
  KccConcrete::set_parameters(const KccParameters &parameters)
  {
    par_ = resolve(parameters);
    build_derived();
  }

  void
  KccConcrete::build_derived()
  {
    eos_.set_table(par_.eos_strain, par_.eos_pressure, par_.eos_modulus);
    dif_curves_ = default_dif_curves(par_.compressive_strength);
    field_      = StrengthField(par_.strength_modulus, par_.strength_cell_size, par_.strength_seed);
  }

  void
  KccConcrete::write_resolved_parameters(std::ostream &out) const
  {
    const KccParameters &p = par_;
    std::ostringstream   s;
    s.precision(10);
    const auto set = [&](const char *key, const auto &value) { s << "    set " << key << " = " << value << "\n"; };
    s << "    # resolved K&C set (generated from f'c = " << p.compressive_strength
      << " Pa where the input says auto)\n";
    set("model", "kcc");
    set("density", p.density);
    set("poisson's ratio", p.poissons_ratio);
    set("compressive strength", p.compressive_strength);
    set("tensile strength", p.tensile_strength);
    set("a0", p.a0);
    set("a1", p.a1);
    set("a2", p.a2);
    set("a0y", p.a0y);
    set("a1y", p.a1y);
    set("a2y", p.a2y);
    set("a1f", p.a1f);
    set("a2f", p.a2f);
    set("b1", p.b1);
    set("b2", p.b2);
    set("b3", p.b3);
    set("omega", p.omega);
    set("edrop", p.edrop);
    set("damage table", table_text({&p.lambda, &p.eta}));
    set("eos table", table_text({&p.eos_strain, &p.eos_pressure, &p.eos_modulus}));
    if (p.shear_modulus > 0.)
      set("shear modulus", p.shear_modulus);
    else
      set("shear modulus", "auto");
    set("rate effects", p.rate_effects ? "true" : "false");
    set("compression DIF", p.dif_c_rate.empty() ? std::string("default") : table_text({&p.dif_c_rate, &p.dif_c}));
    set("tension DIF", p.dif_t_rate.empty() ? std::string("default") : table_text({&p.dif_t_rate, &p.dif_t}));
    set("compression DIF cap", p.dif_c_cap);
    set("tension DIF cap", p.dif_t_cap);
    set("localization width", p.localization_width);
    set("failure scaled damage", p.failure_scaled_damage);
    set("strength modulus", p.strength_modulus);
    set("strength cell size", p.strength_cell_size);
    set("strength seed", p.strength_seed);
    s << "    # derived: f'c on the maximum surface = " << p.fc << " Pa, f'yc = " << p.fyc
      << " Pa, psi_uc = " << p.psi_uc << ", psi_bc = " << p.psi_bc << ", lambda_m = " << p.lambda_m
      << ", initial K = " << p.eos_modulus.front() << " Pa, G = " << shear_modulus(p.eos_modulus.front())
      << " Pa\n";
    out << s.str();
  }

  double
  KccConcrete::density() const
  {
    return par_.density;
  }

  double
  KccConcrete::shear_modulus(const double bulk) const
  {
    if (par_.shear_modulus > 0.)
      return par_.shear_modulus;
    const double nu = par_.poissons_ratio;
    return 1.5 * bulk * (1. - 2. * nu) / (1. + nu);
  }

  double
  KccConcrete::initial_wave_speed() const
  {
    const double k = par_.eos_modulus.front();
    return std::sqrt((k + 4. / 3. * shear_modulus(k)) / par_.density);
  }

  std::array<double, 2>
  KccConcrete::elastic_moduli() const
  {
    const double k = par_.eos_modulus.front();
    return {{k, shear_modulus(k)}};
  }

  std::vector<std::string>
  KccConcrete::state_slot_names() const
  {
    return {slot::plastic_strain,      slot::failed,    "damage lambda",         "scaled damage",
            "plastic volumetric strain", "max compaction", "effective strain rate", "rate factor",
            "strength factor"};
  }

  void
  KccConcrete::initialize_state(const unsigned int n, double *state) const
  {
    std::fill(state, state + static_cast<std::size_t>(n) * n_slots, 0.);
    for (unsigned int i = 0; i < n; ++i)
      state[i * n_slots + slot_rate_factor] = state[i * n_slots + slot_strength] = 1.;
  }

  void
  KccConcrete::set_position_fields(const unsigned int n, const double *positions, double *state) const
  {
    for (unsigned int i = 0; i < n; ++i)
      state[i * n_slots + slot_strength] = field_.factor(positions + 3 * i);
  }

  // --------------------------------------------------------------------------------------
  // The model's functions
  // --------------------------------------------------------------------------------------

  double
  KccConcrete::psi(const double p) const
  {
    const double fc = par_.fc;
    if (p <= 0.)
      return 0.5;
    const double p1 = fc / 3., p2 = 2. * biaxial_ratio * fc / 3., p3 = 3. * fc, p4 = 8.45 * fc;
    if (p < p1)
      return 0.5 + (par_.psi_uc - 0.5) * p / p1;
    if (p < p2)
      return par_.psi_uc + (par_.psi_bc - par_.psi_uc) * (p - p1) / (p2 - p1);
    if (p < p3)
      return par_.psi_bc + (0.753 - par_.psi_bc) * (p - p2) / (p3 - p2);
    if (p < p4)
      return 0.753 + (1. - 0.753) * (p - p3) / (p4 - p3);
    return 1.;
  }

  double
  KccConcrete::max_surface(const double p) const
  {
    const KccParameters &k = par_;
    if (p >= k.fc / 3.)
      return k.a0 + p / (k.a1 + k.a2 * p);
    if (p >= 0.)
      return 1.5 * (p + k.tensile_strength) / psi(p);
    return 3. * (p + k.tensile_strength);
  }

  double
  KccConcrete::yield_surface(const double p) const
  {
    const KccParameters &k = par_;
    if (p >= k.fyc / 3.)
      return k.a0y + p / (k.a1y + k.a2y * p);
    if (p >= 0.)
      return 1.35 * k.tensile_strength + 3. * p * (1. - 1.35 * k.tensile_strength / k.fyc);
    return 1.35 * (p + k.tensile_strength);
  }

  double
  KccConcrete::residual_surface(const double p) const
  {
    return p > 0. ? p / (par_.a1f + par_.a2f * p) : 0.;
  }

  double
  KccConcrete::willam_warnke(const double c, const double psi)
  {
    const double a   = 1. - psi * psi;
    const double rad = std::max(4. * a * c * c + 5. * psi * psi - 4. * psi, 0.);
    const double num = 2. * a * c + (2. * psi - 1.) * std::sqrt(rad);
    const double den = 4. * a * c * c + (1. - 2. * psi) * (1. - 2. * psi);
    return den > 0. ? num / den : 1.;
  }

  double
  KccConcrete::cos_lode_angle(const double *s)
  {
    const double j2 = 0.5 * internal::contract(s, s);
    if (!(j2 > 0.))
      return 0.5;
    const double j3 = s[0] * s[1] * s[2] + 2. * s[3] * s[4] * s[5] - s[0] * s[3] * s[3] -
                      s[1] * s[4] * s[4] - s[2] * s[5] * s[5];
    const double c3 = std::clamp(1.5 * std::sqrt(3.) * j3 / (j2 * std::sqrt(j2)), -1., 1.);
    return std::cos(std::acos(c3) / 3.);
  }

  double
  KccConcrete::eta(const double lambda, const double stretch) const
  {
    const double lm = par_.lambda_m;
    const double lt = lambda <= lm ? lambda : lm + (lambda - lm) / stretch;
    return interpolate(par_.lambda, par_.eta, lt);
  }

  double
  KccConcrete::current_surface(const double p, const double lambda, const double rf,
                               const double stretch) const
  {
    const double ph = p / rf;
    const double e  = eta(lambda, stretch);
    double       ds;
    if (lambda <= par_.lambda_m)
      {
        const double y = yield_surface(ph);
        ds             = y + e * (max_surface(ph) - y);
      }
    else if (ph >= 0.)
      {
        const double r = residual_surface(ph);
        ds             = r + e * (max_surface(ph) - r);
      }
    else
      ds = 3. * (ph + e * par_.tensile_strength);
    return rf * std::max(ds, 0.);
  }

  double
  KccConcrete::tensile_limit(const double lambda, const double rf, const double stretch) const
  {
    const double e = lambda <= par_.lambda_m ? 1. : eta(lambda, stretch);
    return -rf * e * par_.tensile_strength;
  }

  double
  KccConcrete::scaled_damage(const double lambda, const double stretch) const
  {
    const double lm = par_.lambda_m;
    if (lambda <= lm)
      return lm > 0. ? 2. * lambda / (lambda + lm) : 1.;
    return 2. - eta(lambda, stretch);
  }

  KccConcrete::DifCurves
  KccConcrete::default_dif_curves(const double fc)
  {
    const double fc10  = fc / 10e6;
    const double delta = 1. / (1. + 8. * fc10);
    const double alpha = 1. / (5. + 9. * fc10);
    return {1.026 * alpha, std::pow(10., 6.156 * alpha - 2.), delta, std::pow(10., 6. * delta - 2.)};
  }

  double
  KccConcrete::default_dif(const DifCurves &curves, const double rate, const bool tension)
  {
    if (!(rate > 0.))
      return 1.;
    double dif;
    if (tension)
      {
        const double ratio = rate / 1e-6;
        dif = rate <= 1. ? std::pow(ratio, curves.tension_exponent) : curves.tension_factor * std::cbrt(ratio);
      }
    else
      {
        const double ratio = rate / 30e-6;
        dif = rate <= 30. ? std::pow(ratio, curves.compression_exponent)
                          : curves.compression_factor * std::cbrt(ratio);
      }
    return std::max(dif, 1.);
  }

  double
  KccConcrete::default_dif(const double rate, const double fc, const bool tension)
  {
    return default_dif(default_dif_curves(fc), rate, tension);
  }

  double
  KccConcrete::dynamic_increase_factor(const double rate, const bool tension) const
  {
    if (!par_.rate_effects)
      return 1.;
    const std::vector<double> &r = tension ? par_.dif_t_rate : par_.dif_c_rate;
    double                     dif;
    if (r.empty())
      dif = default_dif(dif_curves_, rate, tension);
    else
      {
        const std::vector<double> &d = tension ? par_.dif_t : par_.dif_c;
        if (!(rate > r.front()))
          dif = d.front();
        else if (rate >= r.back())
          dif = d.back();
        else
          {
            const auto        it = std::upper_bound(r.begin(), r.end(), rate);
            const std::size_t k  = static_cast<std::size_t>(it - r.begin()) - 1;
            const double      w  = std::log(rate / r[k]) / std::log(r[k + 1] / r[k]);
            dif                  = d[k] + w * (d[k + 1] - d[k]);
          }
      }
    const double cap = tension ? par_.dif_t_cap : par_.dif_c_cap;
    return cap > 0. ? std::min(dif, cap) : dif;
  }

  // --------------------------------------------------------------------------------------
  // Stress update
  // --------------------------------------------------------------------------------------

  void
  KccConcrete::update(const PointBatch &batch) const
  {
    const double inv_dt = batch.dt > 0. ? 1. / batch.dt : 0.;
    const double m0     = par_.density * initial_wave_speed() * initial_wave_speed();

    for (unsigned int i = 0; i < batch.n; ++i)
      {
        const double *de      = batch.strain_increment + n_sym * i;
        double       *sig     = batch.stress + n_sym * i;
        double       *st      = batch.state + n_slots * i;
        const double  h       = batch.characteristic_length != nullptr ? batch.characteristic_length[i] : 0.;
        const double  stretch = (par_.localization_width > 0. && h > 0.) ? par_.localization_width / h : 1.;

        // Rate of the step: effective rate of the whole rate of deformation.
        const double e_eff   = std::sqrt((2. / 3.) * internal::contract(de, de));
        const double rate    = e_eff * inv_dt;
        st[slot_strain_rate] = rate;
        const double ev      = std::log(batch.relative_volume[i]);
        const double tr      = de[0] + de[1] + de[2];

        // Sub-increments in tension (doc/materials/kcc.md, decision 12). The damage increment
        // of the return is evaluated at the trial pressure; a step that goes far past the
        // tensile peak puts it far beyond -f't, where the base of the damage denominator is
        // floored and lambda grows up to 500 times too fast: the point jumps to full damage in
        // one step and the result depends on the step. A step that opens the volume, ends with a
        // tensile trial pressure and has an elastic stress increment M0 e above
        // max_tension_increment f't is split into equal parts (at most max_tension_substeps),
        // each with the tension rate factor of the whole step.
        unsigned int n_sub = 1;
        if (tr > 0. && par_.tensile_strength > 0.)
          {
            const double ratio = m0 * std::max(e_eff, tr) / (max_tension_increment * par_.tensile_strength);
            if (ratio > 1.)
              {
                const double p_trial =
                  eos_.evaluate(-(ev - st[slot_plastic_volume]), st[slot_max_compaction]).pressure;
                if (p_trial < 0.)
                  n_sub = static_cast<unsigned int>(std::min(std::ceil(ratio), double(max_tension_substeps)));
              }
          }
        double wave = 0.;
        if (n_sub == 1)
          wave = update_point(de, ev, rate, 0., stretch, sig, st);
        else
          {
            double part[n_sym];
            for (unsigned int c = 0; c < n_sym; ++c)
              part[c] = de[c] / n_sub;
            const double rf = dynamic_increase_factor(rate, true);
            for (unsigned int sub = 1; sub <= n_sub; ++sub)
              wave = update_point(part, ev - (1. - double(sub) / n_sub) * tr, rate, rf, stretch, sig, st);
          }
        if (batch.wave_speed != nullptr)
          batch.wave_speed[i] = wave;
      }
  }

  double
  KccConcrete::update_point(const double *de,
                            const double  ev,
                            const double  rate,
                            const double  rate_factor,
                            const double  stretch,
                            double       *sig,
                            double       *st) const
  {
    const KccParameters &k     = par_;
    const double         ft    = k.tensile_strength;
    const double         lm    = k.lambda_m;
    const std::size_t    n_tab = k.lambda.size();

    // 1-2. EOS at the trial volumetric state; G from its unloading modulus.
    double       ev_p  = st[slot_plastic_volume];
    double       x     = -(ev - ev_p);
    auto         eos   = eos_.evaluate(x, st[slot_max_compaction]);
    double       p     = eos.pressure;
    const double g     = shear_modulus(eos.unloading_modulus);
    double       s[n_sym];
    double       d[n_sym];
    internal::deviator(de, d);
    internal::trial_deviator(sig, d, 2. * g, s);

    // 3. Rate factor, fixed within the step: tension curve when the trial pressure is < 0.
    // The strength factor of the point (decision 13) scales the surfaces as the rate factor does.
    const double dif     = rate_factor > 0. ? rate_factor : dynamic_increase_factor(rate, p < 0.);
    st[slot_rate_factor] = dif;
    const double rf      = dif * st[slot_strength];
    const double ph      = p / rf;

    // 4-5. Trial check: r' lies in [psi, 1], so q <= psi Y_c is elastic without the angle.
    double       lambda = st[slot_lambda];
    const double q      = std::sqrt(1.5 * internal::contract(s, s));
    const double yc     = current_surface(p, lambda, rf, stretch);
    const double psi_p  = psi(ph);
    double       cos_theta = 1.;
    bool         have_angle = false; // cos_theta is that of s (scaling keeps the angle)
    bool         returned   = false; // last_limit is r' Y at the final p and lambda
    double       last_d     = -1.;
    double       last_limit = 0.;
    double scale = 1.;
    double dp    = 0.; // increment of effective plastic strain
    if (q > psi_p * yc)
      {
        cos_theta       = cos_lode_angle(s);
        have_angle      = true;
        const double rp = willam_warnke(cos_theta, psi_p);
        if (q > rp * yc)
          {
            // 6-9. Consistency with the dilatancy coupled in (design 5, open point 6):
            //   g(D) = q* - 3G D - r'(theta, psi(p(D))) Y(p(D), lambda_n + c D) = 0,
            //   p(D) = EOS(x* + omega_eff Y'(p*) D).
            // The flow direction (Y' at the trial pressure, omega_eff at lambda_n) and the
            // damage denominator c are frozen at the trial state. Coupling the pressure is
            // what keeps a dilatant, pressure-sensitive point stable under lateral stress
            // control: the one-pass order (dilatancy after the return) gives a negative
            // lateral stiffness just before the peak.
            const double base    = std::max(1. + ph / ft, damage_base_floor);
            const double c       = 1. / (rf * std::pow(base, ph >= 0. ? k.b1 : k.b2));
            const double three_g = 3. * g;
            const double omega_eff =
              lambda > lm && k.edrop > 0. ? k.omega * std::pow(eta(lambda, stretch), k.edrop) : k.omega;
            double dilatancy = 0.; // d eps_v^p / d D
            if (omega_eff > 0.)
              {
                const double hp   = 1e-6 * std::max(std::abs(p), rf * ft);
                const auto   yfun = [&](const double pp) {
                  return willam_warnke(cos_theta, psi(pp / rf)) * current_surface(pp, lambda, rf, stretch);
                };
                dilatancy = omega_eff * std::max((yfun(p + hp) - yfun(p - hp)) / (2. * hp), 0.);
              }
            const double x_trial = x;
            const double x_max_n = st[slot_max_compaction];
            const auto   pressure = [&](const double dd) {
              return dilatancy > 0. ? eos_.pressure(x_trial + dilatancy * dd, x_max_n) : p;
            };
            const auto gfun = [&](const double dd) {
              const double pd = pressure(dd);
              last_d          = dd;
              last_limit =
                willam_warnke(cos_theta, psi(pd / rf)) * current_surface(pd, lambda + c * dd, rf, stretch);
              return q - three_g * dd - last_limit;
            };
            // Bracket: walk the rows of the damage table (eta is linear between them), then
            // secant steps inside the bracketing row, where g is smooth up to the EOS and
            // psi breakpoints.
            const double d_max = q / three_g;
            double       ds = 0., gs = q - rp * yc, de_ = d_max, ge = 0.;
            bool         bracketed = false; // g(d_max) is needed only without a row bracket
            for (std::size_t t = 0; t < n_tab; ++t)
              {
                const double lt = k.lambda[t] <= lm ? k.lambda[t] : lm + (k.lambda[t] - lm) * stretch;
                if (lt <= lambda)
                  continue;
                const double dt_ = (lt - lambda) / c;
                if (dt_ >= d_max)
                  break;
                const double gt = gfun(dt_);
                if (gt <= 0.)
                  {
                    de_       = dt_;
                    ge        = gt;
                    bracketed = true;
                    break;
                  }
                ds = dt_;
                gs = gt;
              }
            if (!bracketed)
              ge = gfun(d_max);
            // Safeguarded secant inside the bracket [a, b] (g(a) > 0 > g(b)): the secant
            // through the last two iterates when it falls inside, the bisection otherwise or
            // when |g| did not halve. Regula falsi alone keeps the far end of the bracket and
            // converges from one side (four to five evaluations to 1e-12 q).
            double root = de_;
            if (ge < 0.)
              {
                double a = ds, fa = gs, b = de_, fb = ge;
                // The first pair: the bracket ends, the one with the smaller |g| as the later
                // iterate, so that the second secant uses it and the first interior point.
                const bool a_closer = fa < -fb;
                double     x0 = a_closer ? b : a, f0 = a_closer ? fb : fa;
                double     x1 = a_closer ? a : b, f1 = a_closer ? fa : fb;
                for (unsigned int it = 0; it < 100; ++it)
                  {
                    double next = f1 != f0 ? x1 - f1 * (x1 - x0) / (f1 - f0) : 0.5 * (a + b);
                    if (!(next > a && next < b))
                      next = 0.5 * (a + b);
                    const double fr = gfun(next);
                    root            = next;
                    if (std::abs(fr) <= 1e-12 * q || b - a <= 1e-14 * b)
                      break;
                    (fr > 0. ? a : b)   = next;
                    (fr > 0. ? fa : fb) = fr;
                    if (it > 0 && std::abs(fr) > 0.5 * std::abs(f1))
                      {
                        // Slow: a bisection point, then secants from it and the far end.
                        const double mid = 0.5 * (a + b);
                        const double fm  = gfun(mid);
                        root             = mid;
                        if (std::abs(fm) <= 1e-12 * q)
                          break;
                        (fm > 0. ? a : b)   = mid;
                        (fm > 0. ? fa : fb) = fm;
                        x0                  = fm > 0. ? b : a;
                        f0                  = fm > 0. ? fb : fa;
                        x1                  = mid;
                        f1                  = fm;
                        continue;
                      }
                    x0 = x1;
                    f0 = f1;
                    x1 = next;
                    f1 = fr;
                  }
              }
            dp     = std::clamp(root, 0., d_max);
            lambda = lambda + c * dp;
            scale  = (q - three_g * dp) / q;
            if (dilatancy > 0.)
              {
                // x as in g(D), so that the final pressure is the one of the last g(D).
                ev_p += dilatancy * dp;
                x   = x_trial + dilatancy * dp;
                eos = eos_.evaluate(x, x_max_n);
                p   = eos.pressure;
              }
            returned = last_d == dp;
          }
      }
    for (unsigned int c = 0; c < n_sym; ++c)
      s[c] *= scale;

    // 10. Tension cutoff (crack opening), with the volumetric damage of b3; two passes so
    // that the damage of this step lowers the limit, then a last clamp at the final limit.
    for (unsigned int pass = 0; pass < 3; ++pass)
      {
        const double p_min = tensile_limit(lambda, rf, stretch);
        if (!(p < p_min))
          break;
        returned = false;
        const double x_cut =
          std::min(eos_.compaction_at_pressure(p_min, eos.max_compaction), eos.max_compaction);
        const double open  = x_cut - x;
        ev_p += open;
        x = x_cut;
        p = p_min;
        for (double &c : s)
          c = 0.;
        if (pass < 2)
          lambda += k.b3 * open / rf;
      }

    // Keep the final state on or inside the surface at the final pressure (the dilatancy
    // raised p, which normally leaves the point inside). After a return whose last g(D) was
    // at the final D (and no tension cut), that evaluation already holds the limit.
    {
      const double q2 = std::sqrt(1.5 * internal::contract(s, s));
      const double ph2 = p / rf;
      const double y2  = returned ? 0. : current_surface(p, lambda, rf, stretch);
      if (returned ? q2 > last_limit : q2 > psi(ph2) * y2)
        {
          const double lim =
            returned ? last_limit
                     : willam_warnke(have_angle ? cos_theta : cos_lode_angle(s), psi(ph2)) * y2;
          if (q2 > lim)
            {
              dp += (q2 - lim) / (3. * g);
              const double f = lim / q2;
              for (double &c : s)
                c *= f;
            }
        }
    }

    // 11. History and stress.
    st[slot_plastic_strain] += dp;
    st[slot_lambda]         = lambda;
    st[slot_plastic_volume] = ev_p;
    st[slot_max_compaction] = eos.max_compaction;
    st[slot_delta]          = std::max(st[slot_delta], scaled_damage(lambda, stretch));
    if (k.failure_scaled_damage > 0. && st[slot_delta] >= k.failure_scaled_damage)
      st[slot_failed] = 1.;
    sig[0] = s[0] - p;
    sig[1] = s[1] - p;
    sig[2] = s[2] - p;
    sig[3] = s[3];
    sig[4] = s[4];
    sig[5] = s[5];
    const double gw = shear_modulus(eos.unloading_modulus);
    return std::sqrt((eos.wave_modulus + 4. / 3. * gw) / k.density);
  }
} // namespace shard::materials
