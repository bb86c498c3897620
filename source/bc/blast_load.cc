// SPDX-License-Identifier: LGPL-2.1-or-later
#include <shard/bc/blast_load.h>

#include <algorithm>
#include <cmath>
#include <iterator>
#include <sstream>
#include <stdexcept>

namespace shard::bc
{
  namespace
  {
    // Exact unit conversions (international foot and pound).
    constexpr double foot  = 0.3048;          // m
    constexpr double pound = 0.45359237;      // kg
    constexpr double psi   = 6894.757293168;  // Pa

    /// Z in ft/lb^(1/3) per Z in m/kg^(1/3) (2.5208110).
    double
    z_imperial_per_metric()
    {
      return std::cbrt(pound) / foot;
    }

    /**
     * One segment of a Kingery-Bulmash fit: for z_lo <= Z <= z_hi (ft/lb^(1/3)),
     * log10(value) = sum_i c[i] U^i with U = k0 + k1 log10(Z).
     */
    struct Fit
    {
      double       z_lo, z_hi, k0, k1;
      unsigned int n;
      double       c[12];
    };

    // Kingery & Bulmash (1984), ARBRL-TR-02555, in the CONWEP form (imperial units) of
    // Randers-Pehrson & Bannister (1997), ARL-TR-1310. Transcribed from independent public copies
    // and checked against each other (doc/manual/blast.md, "Coefficients"). Two digits differ
    // between copies and were resolved: hemispherical is, second segment, C2 = -0.0260816706301
    // (continuous at the joint and consistent with Swisdak 1994; the ARL-TR-1310 line prints
    // -0.028...), spherical Pr C9 = -0.00397126276058 (Pr/Pso tends to 2 in the acoustic limit).
    // hemispherical, Pso (psi)
    const Fit hemi_pso[] = {
      {0.17, 100.0, -0.756579301809, 1.35034249993, 12, {1.9422502013, -1.6958988741, -0.154159376846, 0.514060730593, 0.0988534365274, -0.293912623038, -0.0268112345019, 0.109097496421, 0.00162846756311, -0.0214631030242, 0.0001456723382, 0.00167847752266}},
    };
    // hemispherical, Pr (psi)
    const Fit hemi_pr[] = {
      {0.17, 100.0, -0.789312405513, 1.36637719229, 12, {2.56431321138, -2.21030870597, -0.218536586295, 0.895319589372, 0.24989009775, -0.569249436807, -0.11791682383, 0.224131161411, 0.0245620259375, -0.0455116002694, -0.00190930738887, 0.00361471193389}},
    };
    // hemispherical, is/W^(1/3) (psi ms/lb^(1/3))
    const Fit hemi_is[] = {
      {0.17, 2.41, 0.832468843425, 3.0760329666, 5, {1.57159240621, -0.502992763686, 0.171335645235, 0.0450176963051, -0.0118964626402}},
      {2.41, 100.0, -2.91358616806, 2.40697745406, 8, {0.719852655584, -0.384519026965, -0.0260816706301, 0.00595798753822, 0.014544526107, -0.00663289334734, -0.00284189327204, 0.0013644816227}},
    };
    // hemispherical, ir/W^(1/3) (psi ms/lb^(1/3))
    const Fit hemi_ir[] = {
      {0.17, 100.0, -0.781951689212, 1.33422049854, 4, {1.75291677799, -0.949516092853, 0.112136118689, -0.0250659183287}},
    };
    // hemispherical, ta/W^(1/3) (ms/lb^(1/3))
    const Fit hemi_ta[] = {
      {0.17, 100.0, -0.755684472698, 1.37784223635, 10, {-0.173607601251, 1.35706496258, 0.052492798645, -0.196563954086, -0.0601770052288, 0.0696360270891, 0.0215297490092, -0.0161658930785, -0.00232531970294, 0.00147752067524}},
    };
    // hemispherical, t0/W^(1/3) (ms/lb^(1/3))
    const Fit hemi_to[] = {
      {0.45, 2.54, -0.1790217052, 5.25099193925, 6, {-0.728671776005, 0.130143717675, 0.134872511954, 0.0391574276906, -0.00475933664702, -0.00428144598008}},
      {2.54, 7.0, -5.85909812338, 9.2996288611, 9, {0.20096507334, -0.0297944268976, 0.030632954288, 0.0183405574086, -0.0173964666211, -0.00106321963633, 0.00562060030977, 0.0001618217499, -0.0006860188944}},
      {7.0, 100.0, -4.92699491141, 3.46349745571, 6, {0.572462469964, 0.0933035304009, -0.0005849420883, -0.00226884995013, -0.00295908591505, 0.00148029868929}},
    };
    // spherical, Pso (psi)
    const Fit sphe_pso[] = {
      {0.134, 100.0, -0.756579301809, 1.35034249993, 9, {1.77284970457, -1.69012801396, 0.00804973591951, 0.336743114941, -0.00516226351334, -0.0809228619888, -0.00478507266747, 0.00793030472242, 0.0007684469735}},
    };
    // spherical, Pr (psi)
    const Fit sphe_pr[] = {
      {0.134, 100.0, -0.756579301809, 1.35034249993, 10, {2.39106134946, -2.21400538997, 0.035119031446, 0.657599992109, 0.0141818951887, -0.243076636231, -0.0158699803158, 0.0492741184234, 0.00227639644004, -0.00397126276058}},
    };
    // spherical, is/W^(1/3) (psi ms/lb^(1/3))
    const Fit sphe_is[] = {
      {0.134, 2.0, 1.04504877747, 3.24299066475, 5, {1.43534136453, -0.443749377691, 0.168825414684, 0.0348138030308, -0.010435192824}},
      {2.0, 100.0, -2.67912519532, 2.30629231803, 9, {0.599008468099, -0.40463292088, -0.0142721946082, 0.00912366316617, -0.0006750681404, -0.00800863718901, 0.00314819515931, 0.00152044783382, -0.0007470265899}},
    };
    // spherical, ir/W^(1/3) (psi ms/lb^(1/3))
    const Fit sphe_ir[] = {
      {0.134, 100.0, -0.757659920369, 1.37882996018, 4, {1.60579280091, -0.903118886091, 0.101771877942, -0.0242139751146}},
    };
    // spherical, ta/W^(1/3) (ms/lb^(1/3))
    const Fit sphe_ta[] = {
      {0.134, 100.0, -0.80501734056, 1.37407043777, 8, {-0.0423733936826, 1.36456871214, -0.0570035692784, -0.182832224796, 0.0118851436014, 0.0432648687627, -0.0007997367834, -0.00436073555033}},
    };
    // spherical, t0/W^(1/3) (ms/lb^(1/3))
    const Fit sphe_to[] = {
      {0.37, 2.24, 0.209440059933, 5.11588554305, 9, {-0.801052722864, 0.164953518069, 0.127788499497, 0.00291430135946, 0.00187957449227, 0.0173413962543, 0.00269739758043, -0.00361976502798, -0.00100926577934}},
      {2.24, 5.75, -5.06778493835, 9.2996288611, 9, {0.115874238335, -0.0297944268969, 0.0306329542941, 0.018340557407, -0.0173964666286, -0.00106321963576, 0.0056206003128, 0.0001618217499, -0.0006860188944}},
      {5.75, 100.0, -4.39590134126, 3.1524725364, 8, {0.50659210403, 0.0967031995552, -0.00801302059667, 0.00482705779732, 0.00187587272287, -0.00246738509321, -0.000841116668, 0.0006193291052}},
    };

    struct FitSet
    {
      const Fit   *fits;
      unsigned int n;
    };

    template <std::size_t N>
    FitSet
    set(const Fit (&f)[N])
    {
      return {f, static_cast<unsigned int>(N)};
    }

    /// The six fits of one burst: Pso, Pr, is, ir, ta, t0.
    std::array<FitSet, 6>
    fits(const Burst burst)
    {
      if (burst == Burst::hemispherical)
        return {{set(hemi_pso), set(hemi_pr), set(hemi_is), set(hemi_ir), set(hemi_ta), set(hemi_to)}};
      return {{set(sphe_pso), set(sphe_pr), set(sphe_is), set(sphe_ir), set(sphe_ta), set(sphe_to)}};
    }

    /// 10^Y of the segment holding @p z_ft; below the first segment its lower end is used.
    double
    evaluate(const FitSet &s, double z_ft)
    {
      if (z_ft < s.fits[0].z_lo)
        z_ft = s.fits[0].z_lo;
      const Fit *f = &s.fits[s.n - 1];
      for (unsigned int k = 0; k < s.n; ++k)
        if (z_ft <= s.fits[k].z_hi)
          {
            f = &s.fits[k];
            break;
          }
      const double u = f->k0 + f->k1 * std::log10(z_ft);
      double       y = 0;
      for (unsigned int i = f->n; i-- > 0;)
        y = y * u + f->c[i];
      return std::pow(10., y);
    }
  } // namespace

  Burst
  parse_burst(const std::string &text)
  {
    if (text == "hemispherical")
      return Burst::hemispherical;
    if (text == "spherical")
      return Burst::spherical;
    throw std::invalid_argument("unknown burst '" + text + "'; must be hemispherical or spherical");
  }

  double
  kb_z_min(const Burst burst)
  {
    return (burst == Burst::hemispherical ? 0.17 : 0.134) / z_imperial_per_metric();
  }

  double
  kb_z_max(const Burst)
  {
    return 100. / z_imperial_per_metric();
  }

  BlastWave
  kingery_bulmash(const double z, const double w, const Burst burst)
  {
    if (!(w > 0) || !std::isfinite(w))
      throw std::domain_error("charge mass must be > 0 kg");
    // A relative slack of 1e-12 lets the ends of the range, converted back from feet, pass.
    if (!(z >= kb_z_min(burst) * (1 - 1e-12) && z <= kb_z_max(burst) * (1 + 1e-12)))
      {
        std::ostringstream s;
        s << "scaled distance Z = " << z << " m/kg^(1/3) is outside the Kingery-Bulmash range "
          << kb_z_min(burst) << " to " << kb_z_max(burst) << " m/kg^(1/3) ("
          << (burst == Burst::hemispherical ? "hemispherical" : "spherical") << " burst)";
        throw std::domain_error(s.str());
      }
    const double z_ft  = std::min(std::max(z * z_imperial_per_metric(), burst == Burst::hemispherical ? 0.17 : 0.134), 100.);
    const double w13   = std::cbrt(w / pound); // lb^(1/3)
    const auto   f     = fits(burst);
    BlastWave    out;
    out.pso = evaluate(f[0], z_ft) * psi;
    out.pr  = evaluate(f[1], z_ft) * psi;
    out.is  = evaluate(f[2], z_ft) * w13 * psi * 1e-3;
    out.ir  = evaluate(f[3], z_ft) * w13 * psi * 1e-3;
    out.ta  = evaluate(f[4], z_ft) * w13 * 1e-3;
    out.t0  = evaluate(f[5], z_ft) * w13 * 1e-3;
    return out;
  }

  double
  friedlander_impulse_ratio(const double b)
  {
    // int_0^1 (1 - s) exp(-b s) ds = sum_n (-b)^n / (n + 2)!, used below b = 0.1 where the closed
    // form loses digits to cancellation (14 terms: remainder below 1e-17).
    if (std::abs(b) < 0.1)
      {
        double term = 0.5, sum = 0;
        for (unsigned int n = 0; n < 14; ++n)
          {
            sum += term;
            term *= -b / (n + 3);
          }
        return sum;
      }
    return 1. / b - (1. - std::exp(-b)) / (b * b);
  }

  double
  Friedlander::pressure(const double tau) const
  {
    if (tau < 0 || tau > duration)
      return 0.;
    const double s = tau / duration;
    return peak * (1. - s) * std::exp(-decay * s);
  }

  double
  Friedlander::impulse() const
  {
    return peak * duration * friedlander_impulse_ratio(decay);
  }

  Friedlander
  Friedlander::from_impulse(const double p, const double i, const double t0)
  {
    Friedlander f;
    f.peak     = p;
    f.duration = t0;
    const double target = i / (p * t0); // the ratio i / (p t0) the pulse must have
    if (!(target < 0.5))
      {
        // No b >= 0 carries this much impulse in t0: a triangle of the same peak and impulse.
        f.decay      = 0;
        f.duration   = 2. * i / p;
        f.lengthened = true;
        return f;
      }
    // The ratio falls monotonically from 1/2 (b = 0) and stays below 1/b: the root lies in
    // (0, 1 / target].
    double lo = 0, hi = 1. / target;
    for (unsigned int k = 0; k < 200 && hi - lo > 1e-13 * hi; ++k)
      {
        const double mid = 0.5 * (lo + hi);
        (friedlander_impulse_ratio(mid) > target ? lo : hi) = mid;
      }
    f.decay = 0.5 * (lo + hi);
    return f;
  }

  double
  oblique_pressure(const double p_incident, const double p_reflected, const double cos_theta)
  {
    if (cos_theta <= 0)
      return p_incident;
    const double c2 = cos_theta * cos_theta;
    return p_reflected * c2 + p_incident * (1. + cos_theta - 2. * c2);
  }

  double
  BlastPoint::pressure(const double t) const
  {
    const double tau = t - wave.ta;
    if (tau < 0)
      return 0.;
    return oblique_pressure(incident.pressure(tau), reflected.pressure(tau), cos_theta);
  }

  BlastCharge::BlastCharge(const double tnt_mass, const std::array<double, 3> &centre, const Burst burst)
    : w_(tnt_mass)
    , centre_(centre)
    , burst_(burst)
  {
    if (!(tnt_mass > 0) || !std::isfinite(tnt_mass))
      throw std::domain_error("charge mass must be > 0 kg");
  }

  double
  BlastCharge::scaled_distance(const std::array<double, 3> &x) const
  {
    return std::hypot(x[0] - centre_[0], x[1] - centre_[1], x[2] - centre_[2]) / std::cbrt(w_);
  }

  BlastPoint
  BlastCharge::at(const std::array<double, 3> &x, const std::array<double, 3> &n) const
  {
    BlastPoint p;
    p.z       = scaled_distance(x);
    p.wave    = kingery_bulmash(p.z, w_, burst_);
    const double r = p.z * std::cbrt(w_);
    // Angle between the outward normal and the direction from the point to the charge.
    const double nl = std::hypot(n[0], n[1], n[2]);
    double       c  = 0;
    for (unsigned int i = 0; i < 3; ++i)
      c += n[i] * (centre_[i] - x[i]);
    p.cos_theta = r > 0 && nl > 0 ? c / (r * nl) : 1.;
    p.incident  = Friedlander::from_impulse(p.wave.pso, p.wave.is, p.wave.t0);
    p.reflected = Friedlander::from_impulse(p.wave.pr, p.wave.ir, p.wave.t0);
    return p;
  }
} // namespace shard::bc
