// SPDX-License-Identifier: LGPL-2.1-or-later
#include <shard/base/function.h>
#include <shard/base/sections.h>
#include <shard/materials/material.h>
#include <shard/output/quantities.h>

#include <deal.II/base/mpi.h>
#include <deal.II/lac/vector.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <map>
#include <sstream>

namespace shard::output
{
  using namespace dealii;

  namespace
  {
    const std::map<std::string, unsigned int> n_args = {
      {"reaction", 2},       {"max_coordinate", 2}, {"min_coordinate", 2},    {"max_radius", 2},
      {"stress", 4},         {"velocity", 4},       {"max_plastic_strain", 1}, {"odd_even", 1},
      {"l2_error", 4},       {"kinetic_energy", 4}, {"stress_range", 2},
      {"mass", 1},           {"mean_velocity", 2},  {"load", 2}};

    int
    axis(const std::string &s)
    {
      return s == "x" ? 0 : s == "y" ? 1 : s == "z" ? 2 : -1;
    }

    /// How the local values of a quantity combine over ranks (Quantities::evaluate()).
    enum Mode
    {
      by_sum       = 0, ///< sum of the local values
      by_maximum   = 1, ///< largest local value
      by_minimum   = 2, ///< smallest local value (stored negated among the maxima)
      by_ratio     = 3, ///< |(s_0, s_1, s_2)| / s_3 of four sums
      by_root_mean = 4, ///< sqrt(s_0 / s_1) of two sums (a mass-weighted RMS)
      by_range     = 5, ///< largest minus smallest value (two maxima: of s and of -s)
      by_mean      = 6  ///< s_0 / s_1 of two sums (a mass-weighted mean)
    };

    /// The local parts of every quantity, in item order, and their reduction over ranks.
    struct LocalParts
    {
      std::vector<int>    mode;
      std::vector<double> sums, maxima, ratios, l2, range_parts;

      /// A quantity of mode @p m (by_sum, by_maximum, by_minimum: @p value is the (negated) local
      /// part; the others append their parts to ratios, l2 or range_parts first).
      void
      add(const int m, const double value)
      {
        mode.push_back(m);
        sums.push_back(m == by_sum ? value : 0.);
        maxima.push_back(m == by_maximum || m == by_minimum ? value : -std::numeric_limits<double>::max());
      }


      /// Reduces the parts over ranks and combines them into one value per quantity.
      /// @note Collective.
      std::vector<double>
      reduce(const MPI_Comm comm)
      {
        Utilities::MPI::sum(sums, comm, sums);
        Utilities::MPI::max(maxima, comm, maxima);
        Utilities::MPI::sum(ratios, comm, ratios);
        Utilities::MPI::sum(l2, comm, l2);
        Utilities::MPI::max(range_parts, comm, range_parts);
        std::vector<double> out(mode.size());
        for (unsigned int i = 0, r = 0, e = 0, g = 0; i < mode.size(); ++i)
          if (mode[i] == by_range)
            {
              out[i] = range_parts[2 * g] + range_parts[2 * g + 1];
              ++g;
            }
          else if (mode[i] == by_ratio)
            {
              const double *s = &ratios[4 * r++];
              out[i]          = s[3] > 0 ? std::sqrt(s[0] * s[0] + s[1] * s[1] + s[2] * s[2]) / s[3] : 0.;
            }
          else if (mode[i] == by_root_mean || mode[i] == by_mean)
            {
              const double *s = &l2[2 * e++];
              out[i]          = s[1] > 0 ? (mode[i] == by_mean ? s[0] / s[1] : std::sqrt(s[0] / s[1])) : 0.;
            }
          else
            out[i] = mode[i] == by_sum ? sums[i] : mode[i] == by_maximum ? maxima[i] : -maxima[i];
        return out;
      }
    };

    /// Sum of the reaction forces of condition @p name along axis @p component (3: the wall normal).
    double
    reaction(const bc::BoundaryConditions &conditions, const std::string &name, const int component)
    {
      const auto &r = conditions.reaction(name);
      if (component == 3)
        {
          const auto n = conditions.wall_normal(name);
          return r[0] * n[0] + r[1] * n[1] + r[2] * n[2];
        }
      return r[component];
    }

    /// Largest @p sign times the deformed coordinate @p component over @p nodes.
    double
    largest_coordinate(const std::vector<unsigned int> &nodes, const int component, const double sign,
                       const mesh::Vector &X, const mesh::Vector &d)
    {
      double value = -std::numeric_limits<double>::max();
      for (const auto j : nodes)
        value = std::max(value, sign * (X.local_element(j + component) + d.local_element(j + component)));
      return value;
    }

    /// Largest deformed distance of @p nodes from the axis @p component through the origin (0 if none).
    double
    largest_radius(const std::vector<unsigned int> &nodes, const int component, const mesh::Vector &X,
                   const mesh::Vector &d)
    {
      double value = 0;
      for (const auto j : nodes)
        {
          double r2 = 0;
          for (unsigned int i = 0; i < 3; ++i)
            if (static_cast<int>(i) != component)
              r2 += std::pow(X.local_element(j + i) + d.local_element(j + i), 2);
          value = std::max(value, std::sqrt(r2));
        }
      return value;
    }

    /// Whether an element or particle of body @p b counts for a quantity of @p body (-1: all).
    bool
    selected(const int body, const unsigned int b)
    {
      return body < 0 || static_cast<int>(b) == body;
    }

    /// Largest effective plastic strain of the local elements and particles of @p body (0 if none).
    double
    largest_plastic_strain(const fe::HexForce &hex, const particles::SpgForce &spg, const int body)
    {
      double value = 0;
      for (unsigned int e = 0; e < hex.n_local_elements(); ++e)
        if (selected(body, hex.body(e)))
          value = std::max(value, hex.state_value(e, materials::slot::plastic_strain));
      for (unsigned int i = 0; i < spg.n_owned(); ++i)
        if (selected(body, spg.particles().body(i)))
          value = std::max(value, spg.state_value(i, materials::slot::plastic_strain));
      return value;
    }

    /// Stress @p component (6: von Mises, 7: pressure) of local @p element or owned @p particle
    /// (0 when neither is set).
    double
    point_stress(const fe::HexForce &hex, const particles::SpgForce &spg, const int element, const int particle,
                 const int component)
    {
      if (element < 0 && particle < 0)
        return 0.;
      const double *s = element >= 0 ? hex.stress(element) : spg.stress(particle);
      return component < 6 ? s[component] : component == 6 ? materials::von_mises_stress(s) : -(s[0] + s[1] + s[2]) / 3.;
    }

    // The sums below are appended from a local array, as evaluate() did before it was split:
    // accumulated in an std::array, they are vectorized differently (no fused multiply-add)
    // and the bits change.

    /// Appends the local sums of the odd-even indicator to @p ratios: sum_I s_I u_I (3) and sum_I |u_I|.
    void
    append_odd_even_sums(const std::vector<unsigned int> &nodes, const std::vector<double> &signs,
                         const mesh::Vector &d, std::vector<double> &ratios)
    {
      double s[4] = {0, 0, 0, 0};
      for (std::size_t n = 0; n < nodes.size(); ++n)
        {
          const double u[3] = {d.local_element(nodes[n]), d.local_element(nodes[n] + 1), d.local_element(nodes[n] + 2)};
          for (unsigned int c = 0; c < 3; ++c)
            s[c] += signs[n] * u[c];
          s[3] += std::sqrt(u[0] * u[0] + u[1] * u[1] + u[2] * u[2]);
        }
      ratios.insert(ratios.end(), s, s + 4);
    }

    /// Local sum of m |v|^2 / 2 over @p nodes.
    double
    kinetic_energy(const std::vector<unsigned int> &nodes, const mesh::Vector &v, const mesh::Vector &mass)
    {
      double value = 0;
      for (const auto j : nodes)
        for (unsigned int c = 0; c < 3; ++c)
          value += 0.5 * mass.local_element(j + c) * v.local_element(j + c) * v.local_element(j + c);
      return value;
    }

    /// Local sum of rho0 V0 over the elements and particles of @p body.
    double
    total_mass(const fe::HexForce &hex, const particles::SpgForce &spg, const int body)
    {
      double value = 0;
      for (unsigned int e = 0; e < hex.n_local_elements(); ++e)
        if (selected(body, hex.body(e)))
          value += hex.material(e).density() * hex.reference_volume(e);
      for (unsigned int i = 0; i < spg.n_owned(); ++i)
        if (selected(body, spg.particles().body(i)))
          value += spg.material(i).density() * spg.particles().volume(i);
      return value;
    }

    /// Appends the local maxima of stress @p component and of its negative over the elements and
    /// particles of @p body to @p range_parts.
    void
    append_stress_extremes(const fe::HexForce &hex, const particles::SpgForce &spg, const int body,
                           const int component, std::vector<double> &range_parts)
    {
      // max - min as two maxima: max of s and max of -s, combined after the reduction.
      double hi = -std::numeric_limits<double>::max(), lo = hi;
      for (unsigned int e = 0; e < hex.n_local_elements(); ++e)
        if (selected(body, hex.body(e)))
          hi = std::max(hi, hex.stress(e)[component]), lo = std::max(lo, -hex.stress(e)[component]);
      for (unsigned int i = 0; i < spg.n_owned(); ++i)
        if (selected(body, spg.particles().body(i)))
          hi = std::max(hi, spg.stress(i)[component]), lo = std::max(lo, -spg.stress(i)[component]);
      range_parts.push_back(hi);
      range_parts.push_back(lo);
    }

    /// Appends the local sums of m v_component and of m over @p nodes to @p l2.
    void
    append_mean_velocity_sums(const std::vector<unsigned int> &nodes, const int component, const mesh::Vector &v,
                              const mesh::Vector &mass, std::vector<double> &l2)
    {
      double s[2] = {0, 0};
      for (const auto j : nodes)
        {
          s[0] += mass.local_element(j) * v.local_element(j + component);
          s[1] += mass.local_element(j);
        }
      l2.insert(l2.end(), s, s + 2);
    }

    /// Appends the local sums of m |u - u_exact(X, t)|^2 and of m over @p nodes to @p l2.
    void
    append_l2_error_sums(FunctionParser<3> &exact, const std::vector<unsigned int> &nodes, const mesh::Vector &X,
                         const mesh::Vector &d, const mesh::Vector &mass, const double t, std::vector<double> &l2)
    {
      exact.set_time(t);
      dealii::Vector<double> u(3);
      double                 s[2] = {0, 0};
      for (const auto j : nodes)
        {
          exact.vector_value(Point<3>(X.local_element(j), X.local_element(j + 1), X.local_element(j + 2)), u);
          double e2 = 0;
          for (unsigned int c = 0; c < 3; ++c)
            e2 += std::pow(d.local_element(j + c) - u[c], 2);
          s[0] += mass.local_element(j) * e2;
          s[1] += mass.local_element(j);
        }
      l2.insert(l2.end(), s, s + 2);
    }
  } // namespace

  bool
  Quantities::declare_parameters(ParameterHandler &prm)
  {
    if (!first_declaration())
      return false;
    prm.enter_subsection(sections::quantities);
    prm.add_parameter("quantities", text_,
                      "Columns added to history.csv: entries 'name = kind arguments' separated by ';'. "
                      "Kinds: reaction <condition> <x|y|z|n>; load <condition> <x|y|z>: sum of the forces a "
                      "traction or blast condition applies at this time (N); max_coordinate <body> <x|y|z>; "
                      "min_coordinate <body> <x|y|z>; max_radius <body> <axis x|y|z> [boundary id]; "
                      "stress <x> <y> <z> <xx|yy|zz|yz|xz|xy|vm|p>; velocity <x> <y> <z> <x|y|z>; "
                      "max_plastic_strain <body|all>; odd_even <particle body>: |sum_I s_I u_I| / sum_I |u_I| with "
                      "s_I = (-1)^(i+j+k) from the particle's lattice indices (1 for a pure checkerboard, near 0 "
                      "for smooth fields); l2_error <body|all> <ux> <uy> <uz>: sqrt(sum_I m_I |u_I - u(X_I, t)|^2 / "
                      "sum_I m_I) over the nodes or particles of the body (lumped mass m_I, physical displacement "
                      "u_I) with the exact displacement u given as three muparser expressions of x, y, z "
                      "(reference coordinates) and t, written without spaces (m); kinetic_energy <body|all> "
                      "<x|y|z> <from> <to>: sum of m_I |v_I|^2 / 2 over the nodes and particles whose reference "
                      "coordinate along the axis lies in [from, to] (J); stress_range <body|all> "
                      "<xx|yy|zz|yz|xz|xy>: largest minus smallest stress component over the elements and "
                      "particles (Pa); mass <body|all>: sum of rho0 V0 over the elements and rho0 V_I over the "
                      "particles, from their volumes, not from the mass vector (kg); mean_velocity <body|all> <x|y|z>: "
                      "sum_I m_I v_I / sum_I m_I over the nodes and particles of the body, the velocity of its "
                      "centre of mass (m/s).");
    prm.leave_subsection();
    return true;
  }

  std::vector<Quantities::Item>
  Quantities::parse(std::string &error) const
  {
    std::vector<Item> items;
    for (const auto &entry : base::split(text_, ';'))
      {
        const auto eq = entry.find('=');
        if (eq == std::string::npos)
          {
            error = "entry '" + entry + "' must have the form 'name = kind arguments'.";
            return {};
          }
        Item it;
        it.name = base::trim(entry.substr(0, eq));
        std::istringstream in(entry.substr(eq + 1));
        in >> it.kind;
        for (std::string w; in >> w;)
          it.args.push_back(w);
        const auto n = n_args.find(it.kind);
        if (n == n_args.end())
          {
            error = "entry '" + entry + "': unknown kind '" + it.kind +
                    "'; known: reaction, max_coordinate, min_coordinate, max_radius, stress, velocity, "
                    "max_plastic_strain, odd_even, l2_error, kinetic_energy, stress_range, mass, mean_velocity, load.";
            return {};
          }
        const bool optional_id = it.kind == "max_radius" && it.args.size() == 3;
        if (it.args.size() != n->second && !optional_id)
          {
            error = "entry '" + entry + "': '" + it.kind + "' takes " + std::to_string(n->second) +
                    " arguments" +
                    (it.kind == "l2_error" ? " (a body or 'all', then three expressions without spaces)" : "") + ".";
            return {};
          }
        // Numbers among the arguments: finite, and a range that selects something.
        const auto number = [&](const std::string &word, const std::string &what) {
          std::size_t used = 0;
          double      x    = 0;
          try
            {
              x = std::stod(word, &used);
            }
          catch (const std::exception &)
            {
              used = 0;
            }
          if (used != word.size() || !std::isfinite(x))
            error = "entry '" + base::trim(entry) + "': " + what + " '" + word + "' is not a finite number.";
          return x;
        };
        if (it.kind == "stress" || it.kind == "velocity")
          for (unsigned int i = 0; i < 3 && error.empty(); ++i)
            number(it.args[i], std::string(1, "xyz"[i]));
        if (it.kind == "kinetic_energy")
          {
            const double from = number(it.args[2], "from");
            const double to   = error.empty() ? number(it.args[3], "to") : 0.;
            if (error.empty() && !(from <= to))
              error = "entry '" + base::trim(entry) + "': from " + it.args[2] + " is larger than to " + it.args[3] +
                      ": the range [from, to] (m) selects nothing.";
          }
        if (optional_id && error.empty())
          {
            const double id = number(it.args[2], "boundary id");
            if (error.empty() && !(id >= 0 && id <= 255 && id == std::floor(id)))
              error = "entry '" + base::trim(entry) + "': boundary id '" + it.args[2] + "' must be a whole number from 0 to 255.";
          }
        if (!error.empty())
          return {};
        if (it.kind == "l2_error")
          try
            {
              it.exact = base::parse_vector_function(it.args[1] + ";" + it.args[2] + ";" + it.args[3], true);
            }
          catch (const std::invalid_argument &e)
            {
              // deal.II appends a stack trace to the parser's reason: keep the reason only.
              std::string why = e.what();
              why             = why.substr(0, why.find(" Stacktrace:"));
              error = "entry '" + base::trim(entry) + "': exact displacement '" + it.args[1] + " " + it.args[2] +
                      " " + it.args[3] + "': " + why;
              return {};
            }
        if (it.kind == "l2_error")
          {
            // At the origin at t = 0 (a constant 1/0, sqrt(-1)); prepare() checks every node.
            const auto where = base::non_finite_at(*it.exact, {Point<3>()}, 0.);
            if (!where.empty())
              {
                error = "entry '" + base::trim(entry) + "': the exact displacement is not finite: " + where + ".";
                return {};
              }
          }
        items.push_back(std::move(it));
      }
    return items;
  }

  void
  Quantities::check_parameters(const base::PrmSource &source) const
  {
    std::string error;
    parse(error);
    if (!error.empty())
      source.fail(sections::quantities + "/quantities", text_, error);
  }

  void
  Quantities::prepare(const mesh::Discretization &discretization, const fe::HexForce &hex,
                      const bc::BoundaryConditions &conditions, const particles::SpgForce &particles,
                      const base::PrmSource &source)
  {
    discretization_ = &discretization;
    hex_            = &hex;
    particles_      = &particles;
    conditions_     = &conditions;
    std::string error;
    items_          = parse(error);
    for (auto &it : items_)
      {
        if (it.kind == "reaction" || it.kind == "load")
          resolve_condition(it, source);
        else if (it.kind == "max_coordinate" || it.kind == "min_coordinate" || it.kind == "max_radius")
          resolve_extent(it, source);
        else if (it.kind == "odd_even")
          resolve_odd_even(it, source);
        else if (it.kind == "max_plastic_strain" || it.kind == "mass")
          resolve_body_or_all(it, source);
        else if (it.kind == "kinetic_energy")
          resolve_kinetic_energy(it, source);
        else if (it.kind == "stress_range")
          {
            resolve_body_or_all(it, source);
            const std::vector<std::string> comps = {"xx", "yy", "zz", "yz", "xz", "xy"};
            it.component = std::find(comps.begin(), comps.end(), it.args[1]) - comps.begin();
            if (it.component == 6)
              fail(source, it, "component must be one of xx, yy, zz, yz, xz, xy.");
          }
        else if (it.kind == "l2_error" || it.kind == "mean_velocity")
          resolve_body_nodes(it, source);
        else // stress, velocity at a reference point
          resolve_point(it, source);
      }
  }

  void
  Quantities::fail(const base::PrmSource &source, const Item &it, const std::string &why) const
  {
    source.fail(sections::quantities + "/quantities", text_, "'" + it.name + " = " + it.kind + " ...': " + why);
  }

  void
  Quantities::resolve_body_or_all(Item &it, const base::PrmSource &source) const
  {
    it.body = it.args[0] == "all" ? -1 : discretization_->body_index(it.args[0]);
    if (it.args[0] != "all" && it.body < 0)
      fail(source, it, "no body named '" + it.args[0] + "'.");
  }

  void
  Quantities::resolve_condition(Item &it, const base::PrmSource &source) const
  {
    const auto &names = conditions_->names();
    if (std::find(names.begin(), names.end(), it.args[0]) == names.end())
      fail(source, it, "no boundary condition named '" + it.args[0] + "'.");
    if (it.kind == "reaction")
      {
        it.component = it.args[1] == "n" ? 3 : axis(it.args[1]);
        if (it.component < 0)
          fail(source, it, "component must be x, y, z or n.");
        return;
      }
    const auto &type = conditions_->type(it.args[0]);
    if (type != "traction" && type != "blast")
      fail(source, it, "condition '" + it.args[0] + "' is a " + type + " condition; load needs traction or blast.");
    it.component = axis(it.args[1]);
    if (it.component < 0)
      fail(source, it, "component must be x, y or z.");
  }

  void
  Quantities::resolve_extent(Item &it, const base::PrmSource &source) const
  {
    const auto &discretization = *discretization_;
    it.body                    = discretization.body_index(it.args[0]);
    it.component               = axis(it.args[1]);
    if (it.body < 0)
      fail(source, it, "no body named '" + it.args[0] + "'.");
    if (it.component < 0)
      fail(source, it, "axis must be x, y or z.");
    if (it.args.size() == 3)
      {
        it.boundary_id = std::stoi(it.args[2]); // a whole number from 0 to 255 (parse())
        if (!discretization.boundary_ids(it.body).count(static_cast<unsigned int>(it.boundary_id)))
          fail(source, it, "body '" + it.args[0] + "' has no faces with boundary id " + it.args[2] +
                             "; its boundary ids are " + discretization.boundary_ids_text(it.body) + ".");
      }
    it.nodes = it.args.size() == 3 ? discretization.boundary_nodes(it.body, it.boundary_id) :
                                     discretization.body_nodes(it.body);
  }

  void
  Quantities::resolve_odd_even(Item &it, const base::PrmSource &source) const
  {
    const auto &set = particles_->particles();
    it.body         = discretization_->body_index(it.args[0]);
    if (it.body < 0 || !set.is_particle_body(it.body))
      fail(source, it, "'" + it.args[0] + "' is not a body made of particles (E - Particles/bodies).");
    // Lattice indices from the lowest corner of the body and the particle spacing.
    double lo[3] = {1e300, 1e300, 1e300};
    for (unsigned int i = 0; i < particles_->n_owned(); ++i)
      if (static_cast<int>(set.body(i)) == it.body)
        for (unsigned int c = 0; c < 3; ++c)
          lo[c] = std::min(lo[c], set.position(i)[c]);
    Utilities::MPI::min(ArrayView<const double>(lo, 3), discretization_->communicator(), ArrayView<double>(lo, 3));
    for (unsigned int i = 0; i < particles_->n_owned(); ++i)
      if (static_cast<int>(set.body(i)) == it.body)
        {
          long sum = 0;
          for (unsigned int c = 0; c < 3; ++c)
            sum += std::lround((set.position(i)[c] - lo[c]) / set.spacing(i)[c]);
          it.nodes.push_back(set.local_dof(i));
          it.signs.push_back(sum % 2 ? -1. : 1.);
        }
  }

  void
  Quantities::resolve_kinetic_energy(Item &it, const base::PrmSource &source) const
  {
    resolve_body_or_all(it, source);
    it.component = axis(it.args[1]);
    if (it.component < 0)
      fail(source, it, "axis must be x, y or z.");
    double range[2];
    for (unsigned int k = 0; k < 2; ++k)
      try
        {
          range[k] = std::stod(it.args[2 + k]);
        }
      catch (const std::exception &)
        {
          fail(source, it, "'" + it.args[2 + k] + "' is not a number (from and to in m).");
        }
    const auto &X = discretization_->reference_positions();
    for (unsigned int k = 0; k < discretization_->bodies().size(); ++k)
      if (it.body < 0 || static_cast<int>(k) == it.body)
        for (const auto j : discretization_->body_nodes(k))
          {
            const double x = X.local_element(j + it.component);
            if (x >= range[0] && x <= range[1])
              it.nodes.push_back(j);
          }
  }

  void
  Quantities::resolve_body_nodes(Item &it, const base::PrmSource &source) const
  {
    resolve_body_or_all(it, source);
    if (it.kind == "mean_velocity" && (it.component = axis(it.args[1])) < 0)
      fail(source, it, "axis must be x, y or z.");
    // Bodies never share nodes, so the owned nodes of all bodies count each node once.
    for (unsigned int k = 0; k < discretization_->bodies().size(); ++k)
      if (it.body < 0 || static_cast<int>(k) == it.body)
        for (const auto j : discretization_->body_nodes(k))
          it.nodes.push_back(j);
    if (it.kind == "l2_error")
      {
        // The exact solution must be finite at every node it is compared at, at t = 0.
        const auto           &X = discretization_->reference_positions();
        std::vector<Point<3>> points;
        for (const auto j : it.nodes)
          points.emplace_back(X.local_element(j), X.local_element(j + 1), X.local_element(j + 2));
        const auto local = base::non_finite_at(*it.exact, points, 0.);
        for (const auto &where : Utilities::MPI::all_gather(discretization_->communicator(), local))
          if (!where.empty())
            fail(source, it, "the exact displacement is not finite: " + where + ".");
      }
  }

  void
  Quantities::resolve_point(Item &it, const base::PrmSource &source) const
  {
    double p[3];
    for (unsigned int i = 0; i < 3; ++i)
      p[i] = std::stod(it.args[i]);
    const std::string c = it.args[3];
    if (it.kind == "stress")
      {
        const std::vector<std::string> comps = {"xx", "yy", "zz", "yz", "xz", "xy", "vm", "p"};
        it.component = std::find(comps.begin(), comps.end(), c) - comps.begin();
        if (it.component == 8)
          fail(source, it, "component must be one of xx, yy, zz, yz, xz, xy, vm, p.");
      }
    else if ((it.component = axis(c)) < 0)
      fail(source, it, "component must be x, y or z.");
    // Owner: the local element (or node) closest to the point; the rank with the
    // smallest distance wins, ties to the lowest rank.
    const auto         comm        = discretization_->communicator();
    const double       best        = it.kind == "stress" ? nearest_stress_point(it, p) : nearest_node(it, p);
    const double       global_best = Utilities::MPI::min(best, comm);
    const unsigned int rank        = Utilities::MPI::this_mpi_process(comm);
    const unsigned int owner       = Utilities::MPI::min(best == global_best ? rank : ~0u, comm);
    it.owns_node = owner == rank;
    if (!it.owns_node)
      it.element = -1, it.particle = -1;
  }

  double
  Quantities::nearest_stress_point(Item &it, const double (&p)[3]) const
  {
    double      best = std::numeric_limits<double>::max();
    const auto &dh   = discretization_->dof_handler();
    for (const auto &cell : dh.active_cell_iterators())
      if (cell->is_locally_owned())
        {
          const auto   ctr     = cell->center();
          const double dist    = std::hypot(ctr[0] - p[0], ctr[1] - p[1], ctr[2] - p[2]);
          const int    element = hex_->element_of_cell(cell->active_cell_index());
          if (dist < best && element >= 0)
            best = dist, it.element = element;
        }
    // Particles carry the stress of particle bodies.
    for (unsigned int i = 0; i < particles_->n_owned(); ++i)
      {
        const auto  &x    = particles_->particles().position(i);
        const double dist = std::hypot(x[0] - p[0], x[1] - p[1], x[2] - p[2]);
        if (dist < best)
          best = dist, it.element = -1, it.particle = static_cast<int>(i);
      }
    return best;
  }

  double
  Quantities::nearest_node(Item &it, const double (&p)[3]) const
  {
    const auto &X    = discretization_->reference_positions();
    double      best = std::numeric_limits<double>::max();
    for (unsigned int j = 0; j < discretization_->partitioner()->locally_owned_size(); j += 3)
      {
        const double dist =
          std::hypot(X.local_element(j) - p[0], X.local_element(j + 1) - p[1], X.local_element(j + 2) - p[2]);
        if (dist < best)
          best = dist, it.node = j;
      }
    return best;
  }

  std::vector<std::string>
  Quantities::names() const
  {
    std::vector<std::string> out;
    for (const auto &it : items_)
      out.push_back(it.name);
    return out;
  }

  std::vector<double>
  Quantities::evaluate(const mesh::Vector &d, const mesh::Vector &v, const mesh::Vector &mass,
                        const double t) const
  {
    const auto &X   = discretization_->reference_positions();
    const auto &hex = *hex_;
    const auto &spg = *particles_;
    LocalParts  parts;
    for (const auto &it : items_)
      {
        if (it.kind == "reaction")
          parts.add(by_sum, reaction(*conditions_, it.args[0], it.component));
        else if (it.kind == "load")
          parts.add(by_sum, conditions_->applied_force(it.args[0], t)[it.component]);
        else if (it.kind == "max_coordinate")
          parts.add(by_maximum, largest_coordinate(it.nodes, it.component, 1., X, d));
        else if (it.kind == "min_coordinate")
          parts.add(by_minimum, largest_coordinate(it.nodes, it.component, -1., X, d));
        else if (it.kind == "max_radius")
          parts.add(by_maximum, largest_radius(it.nodes, it.component, X, d));
        else if (it.kind == "max_plastic_strain")
          parts.add(by_maximum, largest_plastic_strain(hex, spg, it.body));
        else if (it.kind == "stress")
          parts.add(by_sum, point_stress(hex, spg, it.element, it.particle, it.component));
        else if (it.kind == "velocity")
          parts.add(by_sum, it.owns_node ? v.local_element(it.node + it.component) : 0.);
        else if (it.kind == "odd_even")
          {
            append_odd_even_sums(it.nodes, it.signs, d, parts.ratios);
            parts.add(by_ratio, 0.);
          }
        else if (it.kind == "kinetic_energy")
          parts.add(by_sum, kinetic_energy(it.nodes, v, mass));
        else if (it.kind == "mass")
          parts.add(by_sum, total_mass(hex, spg, it.body));
        else if (it.kind == "stress_range")
          {
            append_stress_extremes(hex, spg, it.body, it.component, parts.range_parts);
            parts.add(by_range, 0.);
          }
        else if (it.kind == "mean_velocity")
          {
            append_mean_velocity_sums(it.nodes, it.component, v, mass, parts.l2);
            parts.add(by_mean, 0.);
          }
        else if (it.kind == "l2_error")
          {
            append_l2_error_sums(*it.exact, it.nodes, X, d, mass, t, parts.l2);
            parts.add(by_root_mean, 0.);
          }
        else
          parts.add(by_sum, 0.);
      }
    return parts.reduce(discretization_->communicator());
  }
} // namespace shard::output
