// SPDX-License-Identifier: LGPL-2.1-or-later
// Unit tests of the Kingery-Bulmash blast load (doc/manual/blast.md, "Validation"): KB values
// against independent tabulations of UFC 3-340-02, the Friedlander impulse against the KB
// impulse, the angle-of-incidence limits and the range checks.
#include <shard/bc/blast_load.h>

#include <gtest/gtest.h>

#include <cmath>
#include <stdexcept>
#include <vector>

namespace
{
  using namespace shard::bc;

  /// One row of a reference table: Z (m/kg^(1/3)); Pso, Pr (kPa); is, ir (kPa ms/kg^(1/3));
  /// ta, t0 (ms/kg^(1/3)).
  struct Row
  {
    double z, pso, pr, is, ir, ta, t0;
  };

  // R1: the UFC 3-340-02 curves as tabulated in OpenRadioss (common_source/modules/loads/
  // pblast_mod.F90, commit bd4557ba7503a277d3be5b50e1c64e8a12e0c53f, tables labelled "fig 2-15"
  // (surface burst) and "fig 2-7" (free air)), interpolated as OpenRadioss does (linear in Z,
  // logarithmic in the value) and converted from {g, cm, us, Mbar}; doc/manual/blast.md,
  // "Reference values". t0 at Z = 1 hemispherical is interpolated across a joint of the KB
  // duration fit (1.01 m/kg^(1/3)) and differs by 0.9 %.
  const std::vector<Row> ufc_hemispherical = {
    {1, 1357, 8146, 232.2, 884.9, 0.4675, 1.721},
    {2, 283.8, 1057, 133.5, 363.9, 1.696, 2.050},
    {5, 43.19, 100.7, 59.24, 125.6, 8.244, 3.785},
    {10, 14.81, 31.55, 30.98, 59.33, 21.63, 4.788},
  };
  const std::vector<Row> ufc_spherical = {
    {1, 935.0, 5007, 174.5, 559.1, 0.5318, 1.794},
    {2, 194.7, 646.0, 92.13, 235.8, 1.944, 1.846},
    {5, 31.30, 70.04, 40.62, 83.32, 8.994, 3.333},
    {10, 11.09, 23.31, 21.13, 39.72, 22.72, 4.199},
  };
  // R2: hemispherical table of the fcento100/kingery-bulmash test suite (4 significant figures,
  // consistent with Swisdak 1994), a second tabulation.
  const std::vector<Row> swisdak_hemispherical = {
    {1, 1354, 8152, 236.3, 884.7, 0.467, 1.72},
    {2, 283.7, 1058, 134.6, 363.8, 1.693, 2.053},
    {5, 43.23, 100.9, 59.31, 125.6, 8.242, 3.793},
    {10, 14.89, 31.54, 31.04, 59.33, 21.66, 4.779},
  };

  /// Checks KB at every row for a charge of @p w kg (impulses and times scale with W^(1/3)).
  void
  compare(const std::vector<Row> &table, const Burst burst, const double w, const double tol)
  {
    const double w13 = std::cbrt(w);
    for (const auto &r : table)
      {
        SCOPED_TRACE("Z = " + std::to_string(r.z) + ", W = " + std::to_string(w));
        const BlastWave kb = kingery_bulmash(r.z, w, burst);
        EXPECT_NEAR(kb.pso / (r.pso * 1e3), 1., tol) << "Pso";
        EXPECT_NEAR(kb.pr / (r.pr * 1e3), 1., tol) << "Pr";
        EXPECT_NEAR(kb.is / (r.is * w13), 1., tol) << "is"; // kPa ms = Pa s
        EXPECT_NEAR(kb.ir / (r.ir * w13), 1., tol) << "ir";
        EXPECT_NEAR(kb.ta / (r.ta * 1e-3 * w13), 1., tol) << "ta";
        EXPECT_NEAR(kb.t0 / (r.t0 * 1e-3 * w13), 1., tol) << "t0";
      }
  }

  TEST(BlastLoad, HemisphericalAgainstUfcFigure2_15)
  {
    compare(ufc_hemispherical, Burst::hemispherical, 1., 0.05);
    compare(ufc_hemispherical, Burst::hemispherical, 100., 0.05);
  }

  TEST(BlastLoad, SphericalAgainstUfcFigure2_7)
  {
    compare(ufc_spherical, Burst::spherical, 1., 0.05);
    compare(ufc_spherical, Burst::spherical, 8., 0.05);
  }

  TEST(BlastLoad, HemisphericalAgainstSwisdakTable)
  {
    compare(swisdak_hemispherical, Burst::hemispherical, 1., 0.05);
  }

  // The measured agreement is much closer than 5 %: 2 % covers the known is transcription
  // difference of the OpenRadioss line (1.8 % at Z = 1, doc/manual/blast.md).
  TEST(BlastLoad, AgreementIsWithinTwoPercent)
  {
    compare(ufc_hemispherical, Burst::hemispherical, 1., 0.02);
    compare(ufc_spherical, Burst::spherical, 1., 0.002);
    compare(swisdak_hemispherical, Burst::hemispherical, 1., 0.011);
  }

  /// Composite Simpson integral of f over [a, b] with n (even) intervals.
  template <typename F>
  double
  simpson(const F &f, const double a, const double b, const unsigned int n)
  {
    const double h   = (b - a) / n;
    double       sum = f(a) + f(b);
    for (unsigned int k = 1; k < n; ++k)
      sum += (k % 2 ? 4. : 2.) * f(a + k * h);
    return sum * h / 3.;
  }

  TEST(BlastLoad, FriedlanderImpulseEqualsKbImpulse)
  {
    for (const Burst burst : {Burst::hemispherical, Burst::spherical})
      for (const double z : {0.3, 0.5, 1., 2., 5., 10., 20., 35.})
        {
          SCOPED_TRACE("Z = " + std::to_string(z));
          const double                w = 2.5;
          const BlastCharge           charge(w, {{0, 0, 0}}, burst);
          const std::array<double, 3> x{{0, 0, z * std::cbrt(w)}}, facing{{0, 0, -1}}, side{{1, 0, 0}};
          const BlastPoint            normal = charge.at(x, facing), grazing = charge.at(x, side);
          EXPECT_DOUBLE_EQ(normal.cos_theta, 1.);
          EXPECT_NEAR(grazing.cos_theta, 0., 1e-15);
          // Closed form of the pulse against KB.
          EXPECT_NEAR(normal.reflected.impulse() / normal.wave.ir, 1., 1e-10);
          EXPECT_NEAR(normal.incident.impulse() / normal.wave.is, 1., 1e-10);
          // The pressure history itself, integrated from arrival to the end of the longer phase.
          const double ta = normal.wave.ta;
          const double t1 = ta + normal.reflected.duration, t2 = ta + grazing.incident.duration;
          const double ir = simpson([&](double t) { return normal.pressure(t); }, ta, t1, 20000);
          const double is = simpson([&](double t) { return grazing.pressure(t); }, ta, t2, 20000);
          EXPECT_NEAR(ir / normal.wave.ir, 1., 1e-6);
          EXPECT_NEAR(is / normal.wave.is, 1., 1e-6);
          // Peaks at arrival, nothing before.
          EXPECT_DOUBLE_EQ(normal.pressure(ta), normal.wave.pr);
          EXPECT_DOUBLE_EQ(grazing.pressure(ta), normal.wave.pso);
          EXPECT_EQ(normal.pressure(ta * (1 - 1e-9)), 0.);
        }
  }

  TEST(BlastLoad, FriedlanderImpulseRatioClosedForm)
  {
    // int_0^1 (1 - s) exp(-b s) ds by quadrature against the closed form and its series.
    for (const double b : {0., 1e-6, 0.05, 0.0999, 0.1001, 0.4149, 1.7, 8.84, 14.92, 40.})
      {
        const double q = simpson([&](double s) { return (1 - s) * std::exp(-b * s); }, 0., 1., 4000);
        EXPECT_NEAR(friedlander_impulse_ratio(b), q, 1e-12 * (1 + b)) << "b = " << b;
      }
    EXPECT_DOUBLE_EQ(friedlander_impulse_ratio(0.), 0.5);
  }

  TEST(BlastLoad, DecayCoefficientSolvesImpulse)
  {
    // Values of b from the CONWEP Newton iteration in the research notes (kb_check.py):
    // hemispherical Z = 1: 8.8405 (incident), 14.9186 (reflected); Z = 10: 0.4149, 0.7714.
    const BlastCharge charge(1., {{0, 0, 0}}, Burst::hemispherical);
    const auto        p1 = charge.at({{1, 0, 0}}, {{-1, 0, 0}});
    const auto        p10 = charge.at({{10, 0, 0}}, {{-1, 0, 0}});
    EXPECT_NEAR(p1.incident.decay, 8.8405, 1e-3);
    EXPECT_NEAR(p1.reflected.decay, 14.9186, 1e-3);
    EXPECT_NEAR(p10.incident.decay, 0.4149, 1e-3);
    EXPECT_NEAR(p10.reflected.decay, 0.7714, 1e-3);
    EXPECT_FALSE(p1.reflected.lengthened);
    // No solution when p t0 / i <= 2: a triangle of the same peak and impulse, lengthened.
    const auto f = Friedlander::from_impulse(100., 0.6, 0.01);
    EXPECT_TRUE(f.lengthened);
    EXPECT_EQ(f.decay, 0.);
    EXPECT_DOUBLE_EQ(f.duration, 0.012);
    EXPECT_DOUBLE_EQ(f.impulse(), 0.6);
  }

  TEST(BlastLoad, AngleOfIncidenceLimits)
  {
    const double pso = 283.8e3, pr = 1056e3;
    EXPECT_DOUBLE_EQ(oblique_pressure(pso, pr, 1.), pr);                 // 0 degrees: Pr
    EXPECT_NEAR(oblique_pressure(pso, pr, std::cos(M_PI / 2)), pso, 1e-9); // 90 degrees: Pso
    EXPECT_DOUBLE_EQ(oblique_pressure(pso, pr, -0.5), pso);              // turned away: Pso
    // 45 degrees: Pr / 2 + Pso (1 + sqrt(1/2) - 1) (728.8 kPa at Z = 2 in the research notes).
    EXPECT_NEAR(oblique_pressure(pso, pr, std::sqrt(0.5)), 0.5 * pr + pso * std::sqrt(0.5), 1e-6);
    EXPECT_NEAR(oblique_pressure(pso, pr, std::sqrt(0.5)) / 728.8e3, 1., 1e-3);
    // Through a charge: a face at 60 degrees to the direction of the charge.
    const BlastCharge charge(1., {{0, 0, 0}}, Burst::hemispherical);
    const auto        p = charge.at({{2, 0, 0}}, {{-0.5, std::sqrt(0.75), 0}});
    EXPECT_NEAR(p.cos_theta, 0.5, 1e-14);
    // cos = 1/2: Pr / 4 + Pso (1 + 1/2 - 1/2); 547.9 kPa at Z = 2 in the research notes.
    EXPECT_NEAR(p.pressure(p.wave.ta), 0.25 * p.wave.pr + p.wave.pso, 1e-6 * p.wave.pr);
    EXPECT_NEAR(p.pressure(p.wave.ta) / 547.9e3, 1., 1e-3);
  }

  TEST(BlastLoad, RangeIsChecked)
  {
    EXPECT_NEAR(kb_z_min(Burst::hemispherical), 0.0674, 1e-4);
    EXPECT_NEAR(kb_z_min(Burst::spherical), 0.0532, 1e-4);
    EXPECT_NEAR(kb_z_max(Burst::spherical), 39.67, 1e-2);
    EXPECT_THROW(kingery_bulmash(0.06, 1., Burst::hemispherical), std::domain_error);
    EXPECT_NO_THROW(kingery_bulmash(0.06, 1., Burst::spherical));
    EXPECT_THROW(kingery_bulmash(41., 1., Burst::spherical), std::domain_error);
    EXPECT_THROW(kingery_bulmash(1., -1., Burst::spherical), std::domain_error);
    EXPECT_NO_THROW(kingery_bulmash(kb_z_max(Burst::hemispherical), 1., Burst::hemispherical));
    EXPECT_NO_THROW(kingery_bulmash(kb_z_min(Burst::hemispherical), 1., Burst::hemispherical));
    EXPECT_THROW(BlastCharge(0., {{0, 0, 0}}, Burst::spherical), std::domain_error);
    EXPECT_THROW(parse_burst("cylindrical"), std::invalid_argument);
  }
} // namespace
