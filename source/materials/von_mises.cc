// SPDX-License-Identifier: LGPL-2.1-or-later
/**
 * @file von_mises.cc
 * @brief Multi-linear von Mises plasticity by exact radial return (design/materials.md §9).
 */
#include <shard/materials/von_mises.h>

#include <algorithm>
#include <cmath>
#include <stdexcept>

namespace shard::materials
{
  namespace
  {
    /**
     * Segment of the hardening table that holds @p e: the largest k with e_tab[k] <= e
     * (0 for e below the first point). Tables are short (a handful of rows) and most points
     * sit on the first segments, so a forward scan beats a binary search here.
     */
    inline unsigned int
    find_segment(const double *e_tab, const unsigned int n_rows, const double e)
    {
      unsigned int k = 0;
      while (k + 1 < n_rows && e_tab[k + 1] <= e)
        ++k;
      return k;
    }
  } // namespace

  std::string
  VonMises::model_name() const
  {
    return "von mises";
  }

  void
  VonMises::declare_parameters(dealii::ParameterHandler &prm)
  {
    elasticity_.declare_parameters(prm);
    prm.add_parameter(
      "hardening table",
      hardening_table_,
      "Isotropic hardening curve as rows 'effective plastic strain  yield stress' separated by "
      "';', e.g. '0 400e6; 0.1 450e6'. True (Cauchy) stress against logarithmic plastic strain; "
      "beyond the last row the curve continues with the last slope (flat for a single row). "
      "Unit: 1 and Pa. Range: first plastic strain 0, plastic strains strictly increasing, "
      "yield stresses > 0 and non-decreasing.",
      dealii::Patterns::Anything());
    prm.add_parameter(
      "cowper symonds C",
      cowper_symonds_c_,
      "Cowper-Symonds rate constant C: the flow stress is scaled by R = 1 + (rate/C)^(1/P), "
      "rate being the total effective deviatoric strain rate. 0 switches rate effects off. "
      "Mild steel: 40.4. Unit: 1/s. Range: >= 0.",
      dealii::Patterns::Double(0.));
    prm.add_parameter("cowper symonds P",
                      cowper_symonds_p_,
                      "Cowper-Symonds exponent P in R = 1 + (rate/C)^(1/P). Mild steel: 5. "
                      "Unit: 1. Range: > 0.",
                      dealii::Patterns::Double());
    prm.add_parameter(
      "failure plastic strain",
      failure_plastic_strain_,
      "Effective plastic strain at which the point fails for good: it then carries no "
      "deviatoric stress and no tension, only compressive pressure. 0 switches failure off. "
      "Unit: 1. Range: >= 0.",
      dealii::Patterns::Double(0.));
  }

  void
  VonMises::check_parameters(const base::PrmSource &source, const std::string &path) const
  {
    using internal::number_to_string;
    elasticity_.check_parameters(source, path);

    const std::string table_key = path + "/hardening table";
    std::vector<std::vector<double>> rows;
    try
      {
        rows = base::parse_table(hardening_table_, 2);
      }
    catch (const std::invalid_argument &error)
      {
        source.fail(table_key,
                    hardening_table_,
                    std::string("must be rows 'effective plastic strain  yield stress (Pa)' "
                                "separated by ';' (") +
                      error.what() + ")");
      }
    if (rows.empty())
      source.fail(table_key, hardening_table_, "must have at least one row");
    for (std::size_t k = 0; k < rows.size(); ++k)
      if (rows[k].size() != 2 || !std::isfinite(rows[k][0]) || !std::isfinite(rows[k][1]))
        source.fail(table_key,
                    hardening_table_,
                    "row " + std::to_string(k + 1) + " must hold two finite numbers");
    if (rows[0][0] != 0.)
      source.fail(table_key,
                  hardening_table_,
                  "must start at effective plastic strain 0 (row 1 has " +
                    number_to_string(rows[0][0]) + ")");
    for (std::size_t k = 0; k < rows.size(); ++k)
      {
        if (!(rows[k][1] > 0.))
          source.fail(table_key,
                      hardening_table_,
                      "yield stress must be > 0 Pa (row " + std::to_string(k + 1) + " has " +
                        number_to_string(rows[k][1]) + ")");
        if (k == 0)
          continue;
        if (!(rows[k][0] > rows[k - 1][0]))
          source.fail(table_key,
                      hardening_table_,
                      "must be strictly increasing in plastic strain (row " +
                        std::to_string(k + 1) + " has " + number_to_string(rows[k][0]) +
                        " after " + number_to_string(rows[k - 1][0]) + ")");
        if (rows[k][1] < rows[k - 1][1])
          source.fail(table_key,
                      hardening_table_,
                      "yield stress must not decrease (row " + std::to_string(k + 1) + " has " +
                        number_to_string(rows[k][1]) + " Pa after " +
                        number_to_string(rows[k - 1][1]) + " Pa)");
      }

    if (!(cowper_symonds_c_ >= 0.) || !std::isfinite(cowper_symonds_c_))
      source.fail(path + "/cowper symonds C",
                  number_to_string(cowper_symonds_c_),
                  "must be >= 0 (0 = no rate effect). Unit: 1/s");
    if (!(cowper_symonds_p_ > 0.) || !std::isfinite(cowper_symonds_p_))
      source.fail(path + "/cowper symonds P",
                  number_to_string(cowper_symonds_p_),
                  "must be > 0. Unit: 1");
    if (!(failure_plastic_strain_ >= 0.) || !std::isfinite(failure_plastic_strain_))
      source.fail(path + "/failure plastic strain",
                  number_to_string(failure_plastic_strain_),
                  "must be >= 0 (0 = no failure). Unit: 1");
  }

  void
  VonMises::prepare()
  {
    elasticity_.prepare();

    const std::vector<std::vector<double>> rows = base::parse_table(hardening_table_, 2);
    const std::size_t                      n    = rows.size();
    strain_.resize(n);
    stress_.resize(n);
    slope_.assign(n, 0.);
    for (std::size_t k = 0; k < n; ++k)
      {
        strain_[k] = rows[k][0];
        stress_[k] = rows[k][1];
      }
    for (std::size_t k = 0; k + 1 < n; ++k)
      slope_[k] = (stress_[k + 1] - stress_[k]) / (strain_[k + 1] - strain_[k]);
    if (n > 1)
      slope_[n - 1] = slope_[n - 2];
  }

  double
  VonMises::density() const
  {
    return elasticity_.density();
  }

  double
  VonMises::initial_wave_speed() const
  {
    return elasticity_.wave_speed();
  }

  std::array<double, 2>
  VonMises::elastic_moduli() const
  {
    return {{elasticity_.bulk_modulus(), elasticity_.shear_modulus()}};
  }

  std::vector<std::string>
  VonMises::state_slot_names() const
  {
    return {slot::plastic_strain, slot::failed, "effective strain rate"};
  }

  double
  VonMises::yield_stress(const double plastic_strain) const
  {
    const unsigned int k =
      find_segment(strain_.data(), static_cast<unsigned int>(strain_.size()), plastic_strain);
    return stress_[k] + slope_[k] * (plastic_strain - strain_[k]);
  }

  double
  VonMises::rate_factor(const double strain_rate) const
  {
    if (cowper_symonds_c_ > 0. && strain_rate > 0.)
      return 1. + std::pow(strain_rate / cowper_symonds_c_, 1. / cowper_symonds_p_);
    return 1.;
  }

  void
  VonMises::update(const PointBatch &batch) const
  {
    const double       bulk    = elasticity_.bulk_modulus();
    const double       two_g   = 2. * elasticity_.shear_modulus();
    const double       three_g = 3. * elasticity_.shear_modulus();
    const unsigned int n       = batch.n;

    const unsigned int n_rows = static_cast<unsigned int>(strain_.size());
    const double *__restrict e_tab = strain_.data();
    const double *__restrict s_tab = stress_.data();
    const double *__restrict h_tab = slope_.data();

    const double inv_dt  = batch.dt > 0. ? 1. / batch.dt : 0.;
    const bool   rate_on = cowper_symonds_c_ > 0.;
    const double inv_c   = rate_on ? 1. / cowper_symonds_c_ : 0.;
    const double inv_p   = 1. / cowper_symonds_p_;
    const double e_fail  = failure_plastic_strain_; // 0: off

    const double *__restrict de_all = batch.strain_increment;
    const double *__restrict j_all  = batch.relative_volume;
    double *__restrict sig_all      = batch.stress;
    double *__restrict state_all    = batch.state;

    for (unsigned int i = 0; i < n; ++i)
      {
        const double *de  = de_all + n_sym * i;
        double       *sig = sig_all + n_sym * i;
        double       *st  = state_all + n_slots * i;

        // Deviatoric strain increment and its effective rate sqrt(2/3 de:de) / dt.
        double d[n_sym];
        internal::deviator(de, d);
        const double rate = std::sqrt((2. / 3.) * internal::contract(d, d)) * inv_dt;
        st[slot_strain_rate] = rate;

        const double sig_vol = bulk * std::log(j_all[i]); // -p

        if (st[slot_failed] > 0.5)
          {
            const double compression = std::min(sig_vol, 0.); // -max(p, 0)
            sig[0] = sig[1] = sig[2] = compression;
            sig[3] = sig[4] = sig[5] = 0.;
            continue;
          }

        // Elastic trial deviator and its von Mises stress q* = sqrt(3/2 s*:s*).
        double s[n_sym];
        internal::trial_deviator(sig, d, two_g, s);
        const double q2 = 1.5 * internal::contract(s, s);

        const double e_n = st[slot_plastic_strain];
        unsigned int k   = find_segment(e_tab, n_rows, e_n);
        const double sy0 = s_tab[k] + h_tab[k] * (e_n - e_tab[k]);

        double scale = 1.;
        // The rate factor R >= 1 only raises the yield stress: a trial stress within the static
        // yield surface stays elastic whatever the rate, so the power is evaluated only for
        // trial stresses beyond it (the same result, without a pow() per elastic point).
        const double r = (q2 > sy0 * sy0 && rate_on && rate > 0.) ? 1. + std::pow(rate * inv_c, inv_p) : 1.;
        const double sy = r * sy0;
        if (q2 > sy * sy)
          {
            // Walk the linear segments of f(e) = q* - 3G (e - e_n) - R sigma_y(e), which
            // decreases linearly on each segment: the root is found exactly.
            const double q = std::sqrt(q2);
            double       e = e_n;
            for (;;)
              {
                const double sy_e  = s_tab[k] + h_tab[k] * (e - e_tab[k]);
                const double f     = q - three_g * (e - e_n) - r * sy_e;
                const double delta = f / (three_g + r * h_tab[k]);
                if (k + 1 == n_rows || e + delta <= e_tab[k + 1])
                  {
                    e += delta;
                    break;
                  }
                e = e_tab[k + 1];
                ++k;
              }
            st[slot_plastic_strain] = e;
            if (e_fail > 0. && e >= e_fail)
              {
                st[slot_failed]          = 1.;
                const double compression = std::min(sig_vol, 0.);
                sig[0] = sig[1] = sig[2] = compression;
                sig[3] = sig[4] = sig[5] = 0.;
                continue;
              }
            scale = 1. - three_g * (e - e_n) / q;
          }

        sig[0] = scale * s[0] + sig_vol;
        sig[1] = scale * s[1] + sig_vol;
        sig[2] = scale * s[2] + sig_vol;
        sig[3] = scale * s[3];
        sig[4] = scale * s[4];
        sig[5] = scale * s[5];
      }

    if (batch.wave_speed != nullptr)
      std::fill(batch.wave_speed, batch.wave_speed + n, elasticity_.wave_speed());
  }
} // namespace shard::materials
