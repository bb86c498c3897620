// SPDX-License-Identifier: LGPL-2.1-or-later
#include <shard/materials/material.h>
#include <shard/output/quantities.h>

#include <deal.II/base/mpi.h>

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
      {"stress", 4},         {"velocity", 4},       {"max_plastic_strain", 1}};

    int
    axis(const std::string &s)
    {
      return s == "x" ? 0 : s == "y" ? 1 : s == "z" ? 2 : -1;
    }
  } // namespace

  bool
  Quantities::declare_parameters(ParameterHandler &prm)
  {
    if (declared_)
      return false;
    declared_ = true;
    prm.enter_subsection("K - Quantities");
    prm.add_parameter("quantities", text_,
                      "Columns added to history.csv: entries 'name = kind arguments' separated by ';'. "
                      "Kinds: reaction <condition> <x|y|z|n>; max_coordinate <body> <x|y|z>; "
                      "min_coordinate <body> <x|y|z>; max_radius <body> <axis x|y|z> [boundary id]; "
                      "stress <x> <y> <z> <xx|yy|zz|yz|xz|xy|vm|p>; velocity <x> <y> <z> <x|y|z>; "
                      "max_plastic_strain <body|all>.");
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
                    "max_plastic_strain.";
            return {};
          }
        const bool optional_id = it.kind == "max_radius" && it.args.size() == 3;
        if (it.args.size() != n->second && !optional_id)
          {
            error = "entry '" + entry + "': '" + it.kind + "' takes " + std::to_string(n->second) +
                    " arguments.";
            return {};
          }
        items.push_back(it);
      }
    return items;
  }

  void
  Quantities::check_parameters(const base::PrmSource &source) const
  {
    std::string error;
    parse(error);
    if (!error.empty())
      source.fail("K - Quantities/quantities", text_, error);
  }

  void
  Quantities::prepare(const mesh::Discretization &discretization, const fe::HexForce &hex,
                      const bc::BoundaryConditions &conditions)
  {
    discretization_ = &discretization;
    hex_            = &hex;
    conditions_     = &conditions;
    std::string error;
    items_          = parse(error);
    const auto &X   = discretization.reference_positions();
    const auto  bad = [](const Item &it, const std::string &why) {
      throw base::InputError("K - Quantities/quantities: '" + it.name + " = " + it.kind + " ...': " + why);
    };
    for (auto &it : items_)
      {
        if (it.kind == "reaction")
          {
            const auto &names = conditions.names();
            if (std::find(names.begin(), names.end(), it.args[0]) == names.end())
              bad(it, "no boundary condition named '" + it.args[0] + "'.");
            it.component = it.args[1] == "n" ? 3 : axis(it.args[1]);
            if (it.component < 0)
              bad(it, "component must be x, y, z or n.");
          }
        else if (it.kind == "max_coordinate" || it.kind == "min_coordinate" || it.kind == "max_radius")
          {
            it.body      = discretization.body_index(it.args[0]);
            it.component = axis(it.args[1]);
            if (it.body < 0)
              bad(it, "no body named '" + it.args[0] + "'.");
            if (it.component < 0)
              bad(it, "axis must be x, y or z.");
            if (it.args.size() == 3)
              it.boundary_id = std::stoi(it.args[2]);
            it.nodes = it.args.size() == 3 ? discretization.boundary_nodes(it.body, it.boundary_id) :
                                             discretization.body_nodes(it.body);
          }
        else if (it.kind == "max_plastic_strain")
          {
            it.body = it.args[0] == "all" ? -1 : discretization.body_index(it.args[0]);
            if (it.args[0] != "all" && it.body < 0)
              bad(it, "no body named '" + it.args[0] + "'.");
          }
        else // stress, velocity at a reference point
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
                  bad(it, "component must be one of xx, yy, zz, yz, xz, xy, vm, p.");
              }
            else if ((it.component = axis(c)) < 0)
              bad(it, "component must be x, y or z.");
            // Owner: the local element (or node) closest to the point; the rank with the
            // smallest distance wins, ties to the lowest rank.
            double best = std::numeric_limits<double>::max();
            if (it.kind == "stress")
              {
                const auto &dh = discretization.dof_handler();
                for (const auto &cell : dh.active_cell_iterators())
                  if (cell->is_locally_owned())
                    {
                      const auto   ctr  = cell->center();
                      const double dist = std::hypot(ctr[0] - p[0], ctr[1] - p[1], ctr[2] - p[2]);
                      if (dist < best)
                        best = dist, it.element = hex.element_of_cell(cell->active_cell_index());
                    }
              }
            else
              for (unsigned int j = 0; j < discretization.partitioner()->locally_owned_size(); j += 3)
                {
                  const double dist = std::hypot(X.local_element(j) - p[0], X.local_element(j + 1) - p[1],
                                                 X.local_element(j + 2) - p[2]);
                  if (dist < best)
                    best = dist, it.node = j;
                }
            const double global_best = Utilities::MPI::min(best, discretization.communicator());
            const unsigned int rank  = Utilities::MPI::this_mpi_process(discretization.communicator());
            const unsigned int owner = Utilities::MPI::min(best == global_best ? rank : ~0u,
                                                           discretization.communicator());
            it.owns_node = owner == rank;
            if (!it.owns_node)
              it.element = -1;
          }
      }
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
  Quantities::evaluate(const mesh::Vector &d, const mesh::Vector &v) const
  {
    const auto         &X = discretization_->reference_positions();
    const auto          comm = discretization_->communicator();
    std::vector<double> sums, maxima;
    std::vector<int>    mode; // 0 sum, 1 max, 2 min (stored negated in maxima)
    for (const auto &it : items_)
      {
        double value = 0;
        int    m     = 0;
        if (it.kind == "reaction")
          {
            const auto &r = conditions_->reaction(it.args[0]);
            if (it.component == 3)
              {
                const auto n = conditions_->wall_normal(it.args[0]);
                value        = r[0] * n[0] + r[1] * n[1] + r[2] * n[2];
              }
            else
              value = r[it.component];
          }
        else if (it.kind == "max_coordinate" || it.kind == "min_coordinate")
          {
            const double sign = it.kind == "max_coordinate" ? 1. : -1.;
            value             = -std::numeric_limits<double>::max();
            for (const auto j : it.nodes)
              value = std::max(value, sign * (X.local_element(j + it.component) + d.local_element(j + it.component)));
            m = it.kind == "max_coordinate" ? 1 : 2;
          }
        else if (it.kind == "max_radius")
          {
            value = 0;
            for (const auto j : it.nodes)
              {
                double r2 = 0;
                for (unsigned int i = 0; i < 3; ++i)
                  if (static_cast<int>(i) != it.component)
                    r2 += std::pow(X.local_element(j + i) + d.local_element(j + i), 2);
                value = std::max(value, std::sqrt(r2));
              }
            m = 1;
          }
        else if (it.kind == "max_plastic_strain")
          {
            for (unsigned int e = 0; e < hex_->n_local_elements(); ++e)
              if (it.body < 0 || static_cast<int>(hex_->body(e)) == it.body)
                value = std::max(value, hex_->state_value(e, materials::slot::plastic_strain));
            m = 1;
          }
        else if (it.kind == "stress")
          {
            if (it.element >= 0)
              {
                const double *s = hex_->stress(it.element);
                value           = it.component < 6 ? s[it.component] :
                                  it.component == 6 ? materials::von_mises_stress(s) :
                                                      -(s[0] + s[1] + s[2]) / 3.;
              }
          }
        else if (it.kind == "velocity")
          {
            if (it.owns_node)
              value = v.local_element(it.node + it.component);
          }
        mode.push_back(m);
        sums.push_back(m == 0 ? value : 0.);
        maxima.push_back(m == 0 ? -std::numeric_limits<double>::max() : value);
      }
    Utilities::MPI::sum(sums, comm, sums);
    Utilities::MPI::max(maxima, comm, maxima);
    std::vector<double> out(items_.size());
    for (unsigned int i = 0; i < items_.size(); ++i)
      out[i] = mode[i] == 0 ? sums[i] : mode[i] == 1 ? maxima[i] : -maxima[i];
    return out;
  }
} // namespace shard::output
