// SPDX-License-Identifier: LGPL-2.1-or-later
/**
 * @file material_test.cc
 * @brief The single-material-point driver `shard material-test` (doc/manual/materials.md,
 *        section "Material point driver").
 */
#include <shard/base/sections.h>
#include <shard/base/version.h>
#include <shard/base/plot.h>
#include <shard/driver/material_test.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iomanip>
#include <iostream>
#include <sstream>
#include <stdexcept>
#include <utility>


namespace shard::driver
{
  namespace
  {
    using materials::Material;

    const std::string section = sections::material_test;

    /// `M - Material test/<name>`, the path of a key for messages.
    std::string
    key(const std::string &name)
    {
      return section + "/" + name;
    }

    /// The paths with their parameter-file names, in the order of the Selection.
    const std::pair<LoadPath, const char *> path_table[] = {
      {LoadPath::unconfined_compression, "unconfined compression"},
      {LoadPath::uniaxial_tension, "uniaxial tension"},
      {LoadPath::triaxial_compression, "triaxial compression"},
      {LoadPath::hydrostatic, "hydrostatic"},
      {LoadPath::cyclic, "cyclic"},
      {LoadPath::equal_biaxial_compression, "equal biaxial compression"}};

    /// At most this many steps for the legs of `strain targets` (checked on input).
    constexpr double max_input_steps = 1e6;
    /// At most this many steps in all (guards the hydrostatic phase of the triaxial path).
    constexpr unsigned int max_steps = 10000000;
    /// The hydrostatic phase of the triaxial path gives up below this volumetric strain.
    constexpr double min_hydrostatic_strain = -1.;
    /// Largest lateral strain increment the bracket search tries (1).
    constexpr double max_lateral_increment = 1.;

    /// A number with 12 significant digits (as in a .prm file or a message).
    std::string
    to_text(const double x)
    {
      std::ostringstream s;
      s << std::setprecision(12) << x;
      return s.str();
    }

    /// A number for JSON: non-finite values become null.
    std::string
    json_number(const double x)
    {
      return std::isfinite(x) ? to_text(x + 0.) : std::string("null");
    }


    /**
     * Parses "a, b c" (commas and/or white space) into numbers.
     * Throws std::invalid_argument naming the first item that is not a number.
     */
    std::vector<double>
    parse_targets(const std::string &text)
    {
      std::string spaced = text;
      std::replace(spaced.begin(), spaced.end(), ',', ' ');
      return base::parse_numbers(spaced);
    }

    /// Number of steps of the legs 0 -> t_1 -> t_2 ... in steps of at most @p increment.
    unsigned int
    leg_steps(const double span, const double increment)
    {
      // The small allowance keeps 0.01 / 1e-5 at 1000 steps despite rounding.
      return std::max(1u, static_cast<unsigned int>(std::ceil(std::abs(span) / increment - 1e-9)));
    }

    /// Column names of the stress components.
    const char *const stress_names[materials::n_sym] = {"stress_xx", "stress_yy", "stress_zz",
                                                        "stress_yz", "stress_xz", "stress_xy"};

    /// Stops a drive with exit code 3.
    struct DriveFailure
    {
      std::string message;
      /// A stress condition without a solution (limit point), not a model failure.
      bool limit_point = false;
    };

    /**
     * Drives one point: the stepping, the scalar solves and the checks of what the model
     * returns. Every model call works on copies of the stress and state of the last accepted
     * step (Material::update is const and functional), so trial evaluations leave no trace.
     */
    class Driver
    {
    public:
      Driver(const Material &material, const PathControl &control,
             const std::function<void(const PointRecord &)> &record)
        : material_(material)
        , control_(control)
        , record_(record)
        , slot_names_(material.state_slot_names())
      {}

      DriveResult
      run()
      {
        DriveResult result;
        current_.state.assign(slot_names_.size(), 0.);
        if (!current_.state.empty())
          material_.initialize_state(1, current_.state.data());
        current_.wave_speed = material_.initial_wave_speed();
        record_(current_);
        bool hydrostatic_phase = control_.path == LoadPath::triaxial_compression && control_.confinement > 0.;
        try
          {
            if (hydrostatic_phase)
              {
                load_to_confinement();
                result.hydrostatic_steps = current_.step;
                hydrostatic_phase        = false;
              }
            const double origin = current_.strain[0];
            double       c      = 0.;
            for (const double target : control_.targets)
              {
                const double from = c, span = target - from;
                if (span == 0.)
                  continue;
                const unsigned int n = leg_steps(span, control_.strain_increment);
                for (unsigned int k = 1; k <= n; ++k)
                  {
                    c = (k == n) ? target : from + span * k / n;
                    if (control_.path == LoadPath::hydrostatic)
                      hydrostatic_step(c - current_.volumetric_strain());
                    else
                      axial_step(origin + c - current_.strain[0]);
                  }
              }
          }
        catch (const DriveFailure &failure)
          {
            if (hydrostatic_phase)
              result.hydrostatic_steps = current_.step;
            result.exit_code   = failure.limit_point ? 0 : 3;
            result.limit_point = failure.limit_point;
            result.message     = failure.message;
          }
        result.steps = current_.step;
        return result;
      }

    private:
      const Material                                 &material_;
      const PathControl                              &control_;
      const std::function<void(const PointRecord &)> &record_;
      const std::vector<std::string>                  slot_names_;
      PointRecord                                     current_;
      /// Lateral over controlled strain increment of the last axial step: the next first guess.
      double lateral_ratio_ = 0.;

      /// "step N (t = ... s)" of the step being computed.
      std::string
      where(const double dt) const
      {
        return "step " + std::to_string(current_.step + 1) + " (t = " + to_text(current_.time + dt) + " s)";
      }

      /// "strain_xx = ..., strain_yy = ..., strain_zz = ..." of @p p.
      static std::string
      strains(const PointRecord &p)
      {
        return "strain_xx = " + to_text(p.strain[0]) + ", strain_yy = " + to_text(p.strain[1]) +
               ", strain_zz = " + to_text(p.strain[2]);
      }

      /**
       * Calls the model from the last accepted state with the normal strain increments @p de
       * over @p dt; the result goes to @p out. Throws DriveFailure if the model returns a
       * non-finite stress, history value or wave speed.
       */
      void
      evaluate(const std::array<double, 3> &de, const double dt, PointRecord &out) const
      {
        out.time = current_.time + dt;
        out.step = current_.step + 1;
        for (unsigned int d = 0; d < 3; ++d)
          out.strain[d] = current_.strain[d] + de[d];
        out.stress     = current_.stress;
        out.state      = current_.state;
        out.wave_speed = 0.;
        const double increment[materials::n_sym] = {de[0], de[1], de[2], 0., 0., 0.};
        const double relative_volume             = std::exp(out.volumetric_strain());
        const double length                      = control_.characteristic_length;

        materials::PointBatch batch;
        batch.n                     = 1;
        batch.dt                    = dt;
        batch.strain_increment      = increment;
        batch.relative_volume       = &relative_volume;
        batch.characteristic_length = &length;
        batch.stress                = out.stress.data();
        batch.state                 = out.state.empty() ? nullptr : out.state.data();
        batch.wave_speed            = &out.wave_speed;
        material_.update(batch);

        std::string bad;
        double      value = 0.;
        for (unsigned int c = 0; c < materials::n_sym && bad.empty(); ++c)
          if (!std::isfinite(out.stress[c]))
            bad = stress_names[c], value = out.stress[c];
        for (unsigned int s = 0; s < out.state.size() && bad.empty(); ++s)
          if (!std::isfinite(out.state[s]))
            bad = "history slot '" + slot_names_[s] + "'", value = out.state[s];
        if (bad.empty() && !std::isfinite(out.wave_speed))
          bad = "wave_speed", value = out.wave_speed;
        if (!bad.empty())
          throw DriveFailure{where(dt) + ": the material returned a non-finite " + bad + " (" + to_text(value) +
                             ") at " + strains(out) + " (J = " + to_text(relative_volume) + ", dt = " +
                             to_text(dt) + " s)."};
      }

      /// True if residual @p g of the state @p p meets the tolerance of the stress conditions.
      static bool
      converged(const double g, const PointRecord &p)
      {
        const double scale = std::max({std::abs(p.stress[0]), std::abs(p.stress[1]), std::abs(p.stress[2]), 1e6});
        return std::abs(g) <= 1e-9 * scale;
      }

      /// Makes @p p the last accepted state and records it.
      void
      accept(const PointRecord &p)
      {
        if (p.step > max_steps)
          throw DriveFailure{"step " + std::to_string(p.step) + ": more than " + std::to_string(max_steps) +
                             " steps; increase 'strain increment'."};
        current_ = p;
        record_(current_);
      }

      /**
       * Illinois (bracketed secant) iteration for residual(x) = 0 on the bracket [a, b] with
       * residuals @p ga and @p gb of opposite sign; a bisection replaces the secant whenever
       * the bracket has not halved within three iterations. The converged state goes to @p out.
       */
      template <typename Residual>
      double
      illinois(const Residual &residual, double a, double ga, double b, double gb, PointRecord &out,
               const std::string &what, const double dt) const
      {
        PointRecord  trial;
        double       width        = std::abs(b - a);
        unsigned int since_halved = 0;
        for (unsigned int iteration = 0; iteration < 200; ++iteration)
          {
            const double lo = std::min(a, b), hi = std::max(a, b);
            double       x  = 0.5 * (a + b);
            if (since_halved < 3 && gb != ga)
              {
                const double secant = b - gb * (b - a) / (gb - ga);
                if (secant > lo && secant < hi)
                  x = secant;
              }
            if (!(x > lo && x < hi))
              break; // the bracket is down to rounding
            const double g = residual(x, trial);
            if (converged(g, trial))
              {
                out = trial;
                return x;
              }
            if ((g < 0.) == (gb < 0.))
              ga *= 0.5;
            else
              a = b, ga = gb;
            b  = x;
            gb = g;
            if (std::abs(b - a) <= 0.5 * width)
              width = std::abs(b - a), since_halved = 0;
            else
              ++since_halved;
          }
        throw DriveFailure{where(dt) + ": no solution for " + what + ": the residual changes sign from " +
                           to_text(ga) + " Pa to " + to_text(gb) + " Pa between " + to_text(a) + " and " +
                           to_text(b) + " without meeting the tolerance (a jump in the material response)."};
      }

      /**
       * Solves residual(x) = 0 starting at @p x0: widens a bracket from x0 in steps h, 2h, 4h, ...
       * first in the direction a positive stiffness suggests (residual increasing with x), then
       * in the other, up to |x - x0| = 1; then Illinois. The converged state goes to @p out.
       */
      template <typename Residual>
      double
      solve(const Residual &residual, const double x0, const double h, PointRecord &out, const std::string &what,
            const double dt) const
      {
        PointRecord  trial;
        const double g0 = residual(x0, trial);
        if (converged(g0, trial))
          {
            out = trial;
            return x0;
          }
        double closest = g0, closest_x = x0;
        for (unsigned int pass = 0; pass < 2; ++pass)
          {
            const double direction = ((pass == 0) == (g0 > 0.)) ? -1. : 1.;
            double       a = x0, ga = g0;
            for (double step = h; step <= max_lateral_increment; step *= 2.)
              {
                const double b  = x0 + direction * step;
                const double gb = residual(b, trial);
                if (std::abs(gb) < std::abs(closest))
                  closest = gb, closest_x = b;
                if (converged(gb, trial))
                  {
                    out = trial;
                    return b;
                  }
                if ((ga < 0.) != (gb < 0.))
                  return illinois(residual, a, ga, b, gb, out, what, dt);
                // Moving away from the root: try the other side first.
                if (pass == 0 && std::abs(gb) > 10. * std::abs(g0))
                  break;
                a  = b;
                ga = gb;
              }
          }
        throw DriveFailure{where(dt) + ": cannot bracket " + what + ": the residual (stress - target) is " +
                           to_text(g0) + " Pa at the first guess " + to_text(x0) + " and keeps its sign for "
                           "increments up to " + to_text(max_lateral_increment) + " on either side (closest " +
                           to_text(closest) + " Pa at " + to_text(closest_x) + "). The material has no state "
                           "with that stress after this step (e.g. a limit point of a softening response).", true};
      }

      /// One step of the hydrostatic path: all three normal strains grow by @p dv / 3.
      void
      hydrostatic_step(const double dv)
      {
        if (dv == 0.)
          return;
        const double dt = std::abs(dv) / control_.strain_rate;
        PointRecord  next;
        evaluate({{dv / 3., dv / 3., dv / 3.}}, dt, next);
        accept(next);
      }

      /**
       * The first phase of the triaxial path: hydrostatic compression in steps of
       * `strain increment` of ln J until p = confinement; the last step is solved for p.
       */
      void
      load_to_confinement()
      {
        const double inc = control_.strain_increment, target = control_.confinement;
        const auto   residual = [&](const double dv, PointRecord &p) {
          evaluate({{dv / 3., dv / 3., dv / 3.}}, std::abs(dv) / control_.strain_rate, p);
          return p.pressure() - target;
        };
        PointRecord next;
        while (true)
          {
            const double dt = inc / control_.strain_rate;
            if (current_.volumetric_strain() - inc < min_hydrostatic_strain)
              throw DriveFailure{where(dt) + ": the hydrostatic phase of the triaxial path did not reach p = "
                                 "confinement = " + to_text(target) + " Pa before ln J = " +
                                 to_text(min_hydrostatic_strain) + " (p = " + to_text(current_.pressure()) + " Pa)."};
            const double g = residual(-inc, next);
            if (converged(g, next))
              {
                accept(next);
                return;
              }
            if (g < 0.)
              {
                accept(next);
                continue;
              }
            // p passes the confinement within this step: solve for the last increment. The
            // bracket end dv = 0 is the last accepted state (not evaluated: dt would be 0).
            PointRecord last;
            illinois(residual, 0., current_.pressure() - target, -inc, g, last,
                     "p = confinement in the hydrostatic phase", dt);
            accept(last);
            return;
          }
      }

      /**
       * One step with the controlled strain increment @p dc; the one unknown normal strain
       * increment (eps_yy = eps_zz, or eps_zz for equal biaxial) is solved for the lateral
       * stress condition.
       */
      void
      axial_step(const double dc)
      {
        if (dc == 0.)
          return;
        const double dt        = std::abs(dc) / control_.strain_rate;
        const bool   biaxial   = control_.path == LoadPath::equal_biaxial_compression;
        const double lateral   = control_.path == LoadPath::triaxial_compression ? -control_.confinement : 0.;
        const auto   residual  = [&](const double u, PointRecord &p) {
          if (biaxial)
            {
              evaluate({{dc, dc, u}}, dt, p);
              return p.stress[2];
            }
          evaluate({{dc, u, u}}, dt, p);
          return 0.5 * (p.stress[1] + p.stress[2]) - lateral;
        };
        const std::string what =
          biaxial ? std::string("strain_zz with stress_zz = 0")
                  : "strain_yy = strain_zz with stress_yy = stress_zz = " + to_text(lateral) + " Pa";
        PointRecord next;
        const double u = solve(residual, lateral_ratio_ * dc, std::max(std::abs(dc), 1e-12), next, what, dt);
        lateral_ratio_ = u / dc;
        accept(next);
      }
    };

    /// Running extremes and the last row of a drive, for summary.json.
    struct Extremes
    {
      double      peak_compressive_axial_stress = 0.;
      double      peak_tensile_axial_stress     = 0.;
      double      peak_q                        = 0.;
      double      peak_pressure                 = 0.;
      PointRecord last;

      void
      add(const PointRecord &p)
      {
        peak_compressive_axial_stress = std::max(peak_compressive_axial_stress, -p.stress[0]);
        peak_tensile_axial_stress     = std::max(peak_tensile_axial_stress, p.stress[0]);
        peak_q                        = std::max(peak_q, p.q());
        peak_pressure                 = std::max(peak_pressure, p.pressure());
        last                          = p;
      }
    };
  } // namespace

  std::string
  load_path_names()
  {
    std::string names;
    for (const auto &[path, name] : path_table)
      names += (names.empty() ? "" : "|") + std::string(name);
    return names;
  }

  LoadPath
  parse_load_path(const std::string &name)
  {
    for (const auto &[path, n] : path_table)
      if (name == n)
        return path;
    throw std::invalid_argument("unknown path '" + name + "'; one of " + load_path_names());
  }

  std::string
  load_path_name(const LoadPath path)
  {
    for (const auto &[p, name] : path_table)
      if (p == path)
        return name;
    return "?";
  }

  DriveResult
  drive_material_point(const Material &material, const PathControl &control,
                       const std::function<void(const PointRecord &)> &record)
  {
    return Driver(material, control, record).run();
  }

  bool
  MaterialTest::declare_parameters(dealii::ParameterHandler &prm)
  {
    if (!first_declaration())
      return false;
    prm.enter_subsection(section);
    prm.add_parameter("material", material_,
                      "Name of the material to drive. Range: one of 'C - Materials/material names'.",
                      dealii::Patterns::Anything());
    prm.add_parameter(
      "path", path_,
      "Loading path; x is the axial direction, shear strains are zero. 'unconfined compression', "
      "'uniaxial tension', 'cyclic': eps_xx prescribed, sigma_yy = sigma_zz = 0. 'triaxial compression': "
      "hydrostatic loading to p = confinement, then eps_xx prescribed with sigma_yy = sigma_zz = "
      "-confinement. 'hydrostatic': eps_xx = eps_yy = eps_zz, ln J prescribed. 'equal biaxial "
      "compression': eps_xx = eps_yy prescribed, sigma_zz = 0. Range: one of the six names.",
      dealii::Patterns::Selection(load_path_names()));
    prm.add_parameter(
      "strain targets", strain_targets_,
      "Values of the controlled logarithmic strain visited in order starting from 0, separated by "
      "commas or spaces: eps_xx (hydrostatic: the volumetric strain ln J; equal biaxial: eps_xx = "
      "eps_yy; triaxial: eps_xx measured from the end of the hydrostatic phase). E.g. cyclic "
      "'-0.002, -0.001, -0.003'. Unit: 1. Range: each |value| <= 1; <= 0 for unconfined, triaxial and "
      "equal biaxial compression, >= 0 for uniaxial tension; at least one value != 0.",
      dealii::Patterns::Anything());
    prm.add_parameter("strain increment", strain_increment_,
                      "Largest change of the controlled strain per step; each leg between targets is cut "
                      "into equal steps. Also the step of ln J in the hydrostatic phase of the triaxial "
                      "path. Unit: 1. Range: > 0, at most 1e6 steps for the targets.",
                      dealii::Patterns::Double());
    prm.add_parameter("strain rate", strain_rate_,
                      "Magnitude of the controlled strain rate; the time step is |strain step| / rate. "
                      "Unit: 1/s. Range: > 0.",
                      dealii::Patterns::Double());
    prm.add_parameter("confinement", confinement_,
                      "Lateral compressive stress of 'triaxial compression': sigma_yy = sigma_zz = "
                      "-confinement during the axial phase. Only for that path. Unit: Pa. Range: >= 0.",
                      dealii::Patterns::Double());
    prm.add_parameter("characteristic length", characteristic_length_,
                      "Size of the volume the point stands for, passed to the model (regularised "
                      "softening). Unit: m. Range: > 0.",
                      dealii::Patterns::Double());
    prm.add_parameter("output directory", output_directory_,
                      "Directory of history.csv, summary.json, parameters.prm and material_test.png "
                      "(created if missing); relative paths are relative to the working directory. "
                      "Range: a non-empty path.");
    prm.add_parameter("plot", plot_,
                      "Write material_test.png with contrib/utilities/plot_material_test.py "
                      "(/usr/bin/python3 and matplotlib); a failure there only prints a warning. "
                      "Range: true or false.");
    prm.leave_subsection();
    return true;
  }

  void
  MaterialTest::check_parameters(const base::PrmSource &source) const
  {
    const auto &names = materials_.names();
    if (std::find(names.begin(), names.end(), material_) == names.end())
      {
        std::string list;
        for (const auto &n : names)
          list += (list.empty() ? "" : ", ") + n;
        source.fail(key("material"), material_,
                    "no such material in 'C - Materials/material names' (" + list + ").");
      }

    const LoadPath path = parse_load_path(path_);
    std::vector<double> targets;
    try
      {
        targets = parse_targets(strain_targets_);
      }
    catch (const std::invalid_argument &error)
      {
        source.fail(key("strain targets"), strain_targets_,
                    std::string("must be numbers separated by commas or spaces (") + error.what() + ").");
      }
    if (targets.empty())
      source.fail(key("strain targets"), strain_targets_, "at least one strain value is required. Unit: 1");
    bool any_nonzero = false;
    for (std::size_t k = 0; k < targets.size(); ++k)
      {
        const double t    = targets[k];
        const auto   item = "(value " + std::to_string(k + 1) + " is " + to_text(t) + "). Unit: 1";
        if (!std::isfinite(t) || std::abs(t) > 1.)
          source.fail(key("strain targets"), strain_targets_, "each value must be within [-1, 1] " + item);
        if ((path == LoadPath::unconfined_compression || path == LoadPath::triaxial_compression ||
             path == LoadPath::equal_biaxial_compression) &&
            t > 0.)
          source.fail(key("strain targets"), strain_targets_,
                      "must be <= 0 for path = " + path_ + " (compression is negative) " + item);
        if (path == LoadPath::uniaxial_tension && t < 0.)
          source.fail(key("strain targets"), strain_targets_,
                      "must be >= 0 for path = uniaxial tension " + item);
        any_nonzero = any_nonzero || t != 0.;
      }
    if (!any_nonzero)
      source.fail(key("strain targets"), strain_targets_, "at least one value must differ from 0. Unit: 1");

    if (!(strain_increment_ > 0.) || !std::isfinite(strain_increment_))
      source.fail(key("strain increment"), to_text(strain_increment_), "must be > 0. Unit: 1");
    double steps = 0., c = 0.;
    for (const double t : targets)
      {
        if (t != c)
          steps += std::ceil(std::abs(t - c) / strain_increment_ - 1e-9);
        c = t;
      }
    if (steps > max_input_steps)
      source.fail(key("strain increment"), to_text(strain_increment_),
                  "gives " + to_text(steps) + " steps for the strain targets; at most " + to_text(max_input_steps) +
                    " are allowed. Unit: 1");
    if (!(strain_rate_ > 0.) || !std::isfinite(strain_rate_))
      source.fail(key("strain rate"), to_text(strain_rate_), "must be > 0. Unit: 1/s");
    if (!(confinement_ >= 0.) || !std::isfinite(confinement_))
      source.fail(key("confinement"), to_text(confinement_), "must be >= 0. Unit: Pa");
    if (confinement_ > 0. && path != LoadPath::triaxial_compression)
      source.fail(key("confinement"), to_text(confinement_),
                  "is used by path = triaxial compression only (path is " + path_ + "); set 0. Unit: Pa");
    if (!(characteristic_length_ > 0.) || !std::isfinite(characteristic_length_))
      source.fail(key("characteristic length"), to_text(characteristic_length_), "must be > 0. Unit: m");
    if (base::trim(output_directory_).empty())
      source.fail(key("output directory"), output_directory_, "must not be empty.");
  }

  void
  MaterialTest::read(const base::PrmSource &source)
  {
    source_ = source;
    base::read_parameters(prm_, {&materials_, this}, source_);
    control_.path                  = parse_load_path(path_);
    control_.targets               = parse_targets(strain_targets_);
    control_.strain_increment      = strain_increment_;
    control_.strain_rate           = strain_rate_;
    control_.confinement           = confinement_;
    control_.characteristic_length = characteristic_length_;
  }

  void
  MaterialTest::print_parameters(std::ostream &out) const
  {
    prm_.print_parameters(out, dealii::ParameterHandler::PRM | dealii::ParameterHandler::KeepDeclarationOrder);
  }

  DriveResult
  MaterialTest::run(std::ostream &log)
  {
    materials_.prepare();
    const Material &material = materials_.get(material_);
    const auto      slots    = material.state_slot_names();

    std::error_code ec;
    std::filesystem::create_directories(output_directory_, ec);
    if (ec || !std::filesystem::is_directory(output_directory_))
      source_.fail(key("output directory"), output_directory_,
                   "cannot create the directory (" + (ec ? ec.message() : std::string("not a directory")) + ").");
    const std::string dir = output_directory_;
    {
      std::ofstream used(dir + "/parameters.prm");
      prm_.print_parameters(used, dealii::ParameterHandler::ShortPRM | dealii::ParameterHandler::KeepDeclarationOrder);
    }
    materials_.write_resolved_parameters(dir + "/generated_parameters.prm");

    std::ofstream history(dir + "/history.csv");
    if (!history)
      throw std::runtime_error("cannot write '" + dir + "/history.csv'");
    history << "time,step,strain_xx,strain_yy,strain_zz,volumetric_strain,stress_xx,stress_yy,stress_zz,"
               "pressure,q,wave_speed";
    for (std::string name : slots)
      {
        std::replace(name.begin(), name.end(), ' ', '_');
        history << "," << name;
      }
    history << "\n" << std::setprecision(12);

    Extremes   extremes;
    // + 0. writes -0 as 0.
    const auto record = [&](const PointRecord &p) {
      history << p.time << "," << p.step << "," << p.strain[0] + 0. << "," << p.strain[1] + 0. << ","
              << p.strain[2] + 0. << "," << p.volumetric_strain() + 0. << "," << p.stress[0] + 0. << ","
              << p.stress[1] + 0. << "," << p.stress[2] + 0. << "," << p.pressure() + 0. << "," << p.q() << ","
              << p.wave_speed;
      for (const double s : p.state)
        history << "," << s + 0.;
      history << "\n";
      extremes.add(p);
    };
    const DriveResult result = drive_material_point(material, control_, record);
    history.close();

    const PointRecord &last = extremes.last;
    std::ostringstream j;
    j << "{\n";
    j << "  \"shard_version\": \"" << version_string << " (" << git_description << ")\",\n";
    j << "  \"parameter_file\": \"" << base::json_escape(source_.filename()) << "\",\n";
    j << "  \"status\": \"" << (result.exit_code != 0 ? "stopped" : result.limit_point ? "limit point" : "completed")
      << "\",\n";
    if (!result.message.empty())
      j << "  \"message\": \"" << base::json_escape(result.message) << "\",\n";
    j << "  \"path\": \"" << base::json_escape(path_) << "\",\n";
    j << "  \"material\": \"" << base::json_escape(material_) << "\",\n";
    j << "  \"model\": \"" << base::json_escape(material.model_name()) << "\",\n";
    j << "  \"confinement\": " << json_number(confinement_) << ",\n";
    j << "  \"steps\": " << result.steps << ",\n";
    j << "  \"hydrostatic_steps\": " << result.hydrostatic_steps << ",\n";
    j << "  \"peak_compressive_axial_stress\": " << json_number(extremes.peak_compressive_axial_stress) << ",\n";
    j << "  \"peak_tensile_axial_stress\": " << json_number(extremes.peak_tensile_axial_stress) << ",\n";
    j << "  \"peak_q\": " << json_number(extremes.peak_q) << ",\n";
    j << "  \"peak_pressure\": " << json_number(extremes.peak_pressure) << ",\n";
    j << "  \"final_time\": " << json_number(last.time) << ",\n";
    j << "  \"final_strain_xx\": " << json_number(last.strain[0]) << ",\n";
    j << "  \"final_strain_yy\": " << json_number(last.strain[1]) << ",\n";
    j << "  \"final_strain_zz\": " << json_number(last.strain[2]) << ",\n";
    j << "  \"final_volumetric_strain\": " << json_number(last.volumetric_strain()) << ",\n";
    j << "  \"final_stress_xx\": " << json_number(last.stress[0]) << ",\n";
    j << "  \"final_stress_yy\": " << json_number(last.stress[1]) << ",\n";
    j << "  \"final_stress_zz\": " << json_number(last.stress[2]) << ",\n";
    j << "  \"final_pressure\": " << json_number(last.pressure()) << ",\n";
    j << "  \"final_q\": " << json_number(last.q()) << ",\n";
    j << "  \"final_wave_speed\": " << json_number(last.wave_speed) << ",\n";
    j << "  \"final_state\": {";
    for (unsigned int s = 0; s < slots.size(); ++s)
      j << (s ? ", " : "") << "\"" << base::json_escape(slots[s]) << "\": "
        << json_number(s < last.state.size() ? last.state[s] : std::nan(""));
    j << "},\n";
    j << "  \"files\": {\"history\": \"" << base::json_escape(dir) << "/history.csv\", \"parameters\": \""
      << base::json_escape(dir) << "/parameters.prm\"}\n";
    j << "}\n";
    base::write_file_atomically(dir + "/summary.json", j.str());

    log << "material-test: " << material_ << " (" << material.model_name() << "), " << path_
        << (control_.path == LoadPath::triaxial_compression ? ", confinement " + to_text(confinement_ * 1e-6) + " MPa"
                                                            : "")
        << ": " << result.steps << " steps, "
        << (result.exit_code != 0 ? "stopped" : result.limit_point ? "ended at a limit point" : "completed")
        << "; peak compressive axial stress " << to_text(extremes.peak_compressive_axial_stress * 1e-6)
        << " MPa, peak tensile " << to_text(extremes.peak_tensile_axial_stress * 1e-6) << " MPa, peak q "
        << to_text(extremes.peak_q * 1e-6) << " MPa, peak p " << to_text(extremes.peak_pressure * 1e-6)
        << " MPa; results in " << dir << "/" << std::endl;

    if (plot_)
      {
        std::string title = material_ + " (" + material.model_name() + "): " + path_;
        if (control_.path == LoadPath::triaxial_compression)
          title += ", confinement " + to_text(confinement_ * 1e-6) + " MPa";
        const std::string warning = base::run_plot_script(
          "plot_material_test.py", {dir + "/material_test.png", dir + "/history.csv", "--title", title});
        if (!warning.empty())
          log << "material-test: warning: " << warning << std::endl;
      }
    return result;
  }
} // namespace shard::driver
