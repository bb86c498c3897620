// SPDX-License-Identifier: LGPL-2.1-or-later
#include <shard/base/function.h>
#include <shard/bc/boundary_conditions.h>

#include <algorithm>
#include <cmath>

namespace shard::bc
{
  using namespace dealii;

  bool
  BoundaryConditions::declare_parameters(ParameterHandler &prm)
  {
    bool added = false;
    prm.enter_subsection("I - Boundary conditions");
    if (!names_declared_)
      {
        prm.add_parameter("condition names", names_text_,
                          "Comma-separated names of the boundary conditions; each has a subsection. "
                          "Empty: no boundary conditions.");
        names_declared_ = added = true;
      }
    names_ = base::split(names_text_, ',');
    for (const auto &name : names_)
      {
        if (params_.count(name))
          continue;
        added  = true;
        auto &c = *(params_[name] = std::make_unique<ConditionParameters>());
        c.name = name;
        prm.enter_subsection(name);
        prm.add_parameter("type", c.type,
                          "fixed: zero velocity in 'components'; velocity: prescribed velocity 'function' in "
                          "'components'; traction: force per reference area 'function'; rigid wall: "
                          "frictionless plane through 'wall point' with 'wall normal' towards the body.",
                          Patterns::Selection("fixed|velocity|traction|rigid wall"));
        prm.add_parameter("body", c.body, "Name of the body the condition acts on.");
        prm.add_parameter("boundary id", c.boundary_id,
                          "Boundary id of the body's faces (box: 0 x-, 1 x+, 2 y-, 3 y+, 4 z-, 5 z+ in the "
                          "body's own frame; rod and cylinder: 0 hull, 1 start face, 2 end face... see the "
                          "manual); -1: every boundary face of the body. Unit: 1. Range: -1 to 255.",
                          Patterns::Integer(-1, 255));
        prm.add_parameter("components", c.components,
                          "Fixed and velocity: constrained components, a comma-separated subset of x, y, z.");
        prm.add_parameter("function", c.function,
                          "Velocity (m/s) or traction (Pa): three muparser expressions of the reference "
                          "coordinates x, y, z and the time t, separated by ';'.");
        prm.add_parameter("wall point", c.wall_point, "Rigid wall: a point 'x, y, z' on the plane. Unit: m.");
        prm.add_parameter("wall normal", c.wall_normal,
                          "Rigid wall: normal 'x, y, z' pointing towards the body (any length > 0). Unit: 1.");
        prm.leave_subsection();
      }
    prm.leave_subsection();
    return added;
  }

  void
  BoundaryConditions::check_parameters(const base::PrmSource &source) const
  {
    const std::string top = "I - Boundary conditions/";
    base::check_names(source, top + "condition names", names_text_, names_, true);
    for (const auto &name : names_)
      {
        const auto       &c    = *params_.at(name);
        const std::string path = top + name + "/";
        if (c.type == "fixed" || c.type == "velocity")
          {
            const auto comps = base::split(c.components, ',');
            if (comps.empty())
              source.fail(path + "components", c.components, "must name at least one of x, y, z.");
            for (const auto &comp : comps)
              if (comp != "x" && comp != "y" && comp != "z")
                source.fail(path + "components", c.components, "must be a comma-separated subset of x, y, z.");
          }
        if (c.type == "velocity" || c.type == "traction")
          {
            try
              {
                base::parse_vector_function(c.function, true);
              }
            catch (const std::invalid_argument &e)
              {
                source.fail(path + "function", c.function,
                            std::string(e.what()) + "; must be three muparser expressions of x, y, z, t "
                                                    "separated by ';'.");
              }
          }
        if (c.type == "rigid wall")
          {
            try
              {
                base::parse_point(c.wall_point);
              }
            catch (const std::invalid_argument &e)
              {
                source.fail(path + "wall point", c.wall_point, std::string(e.what()) + ".");
              }
            std::array<double, 3> n{};
            try
              {
                n = base::parse_point(c.wall_normal);
              }
            catch (const std::invalid_argument &e)
              {
                source.fail(path + "wall normal", c.wall_normal, std::string(e.what()) + ".");
              }
            if (!(std::hypot(n[0], n[1], n[2]) > 0))
              source.fail(path + "wall normal", c.wall_normal, "must have a length > 0.");
          }
      }
  }

  void
  BoundaryConditions::prepare(const mesh::Discretization &discretization)
  {
    discretization_ = &discretization;
    active_.clear();
    for (const auto &name : names_)
      {
        const auto &c    = *params_.at(name);
        const int   body = discretization.body_index(c.body);
        if (body < 0)
          throw base::InputError("I - Boundary conditions/" + name + "/body = " + c.body +
                                 ": no such body in 'B - Mesh/body names'.");
        Active a;
        a.p = &c;
        if (c.type == "traction")
          a.areas = discretization.boundary_node_areas(body, c.boundary_id);
        else
          a.nodes = discretization.boundary_nodes(body, c.boundary_id);
        if (c.type == "fixed" || c.type == "velocity")
          {
            a.mask = {{false, false, false}};
            for (const auto &comp : base::split(c.components, ','))
              a.mask[comp == "x" ? 0 : comp == "y" ? 1 : 2] = true;
          }
        if (c.type == "velocity" || c.type == "traction")
          {
            a.function  = base::parse_vector_function(c.function, true);
            a.time_only = !base::depends_on_position(c.function);
          }
        if (c.type == "rigid wall")
          {
            a.point      = base::parse_point(c.wall_point);
            const auto n = base::parse_point(c.wall_normal);
            const double l = std::hypot(n[0], n[1], n[2]);
            a.normal     = {{n[0] / l, n[1] / l, n[2] / l}};
          }
        reaction_[name] = {{0, 0, 0}};
        active_.push_back(std::move(a));
      }
    // Walls act last so that they only change the normal velocity left by the other conditions.
    std::stable_partition(active_.begin(), active_.end(),
                          [](const Active &a) { return a.p->type != "rigid wall"; });
  }

  std::array<double, 3>
  BoundaryConditions::wall_normal(const std::string &name) const
  {
    for (const auto &a : active_)
      if (a.p->name == name)
        return a.normal;
    return {{0, 0, 0}};
  }

  void
  BoundaryConditions::add_external_forces(const double t, mesh::Vector &f) const
  {
    const auto &X = discretization_->reference_positions();
    for (const auto &a : active_)
      if (a.p->type == "traction")
        {
          a.function->set_time(t);
          Vector<double> value(3);
          if (a.time_only)
            a.function->vector_value(Point<3>(), value);
          for (const auto &[node, area] : a.areas)
            {
              if (!a.time_only)
                a.function->vector_value(Point<3>(X.local_element(node), X.local_element(node + 1),
                                                  X.local_element(node + 2)),
                                         value);
              for (unsigned int i = 0; i < 3; ++i)
                f.local_element(node + i) += value[i] * area;
            }
        }
  }

  std::pair<double, double>
  BoundaryConditions::apply_kinematic(const double t_half, const double dt_avg, const double dt_next,
                                      const double dt_old, const mesh::Vector &d, const mesh::Vector &mass,
                                      const mesh::Vector &acceleration, mesh::Vector &v)
  {
    const auto &X           = discretization_->reference_positions();
    double      work_before = 0, work_after = 0;
    // Sets v_j and books the reaction m (v_new - v_free) / dt_avg and its work over the
    // half steps before and after this kick.
    const auto constrain = [&](const unsigned int j, const double v_new, std::array<double, 3> &sum,
                               const unsigned int i) {
      const double v_free = v.local_element(j);
      const double r      = mass.local_element(j) * (v_new - v_free) / dt_avg;
      const double v_old  = v_free - dt_avg * acceleration.local_element(j);
      work_before += r * 0.5 * dt_old * v_old;
      work_after += r * 0.5 * dt_next * v_new;
      sum[i] += r;
      v.local_element(j) = v_new;
    };
    for (auto &a : active_)
      {
        auto &sum = reaction_[a.p->name];
        sum       = {{0, 0, 0}};
        if (a.p->type == "fixed")
          {
            for (const unsigned int node : a.nodes)
              for (unsigned int i = 0; i < 3; ++i)
                if (a.mask[i])
                  constrain(node + i, 0., sum, i);
          }
        else if (a.p->type == "velocity")
          {
            a.function->set_time(t_half);
            Vector<double> value(3);
            if (a.time_only)
              a.function->vector_value(Point<3>(), value);
            for (const unsigned int node : a.nodes)
              {
                if (!a.time_only)
                  a.function->vector_value(Point<3>(X.local_element(node), X.local_element(node + 1),
                                                    X.local_element(node + 2)),
                                           value);
                for (unsigned int i = 0; i < 3; ++i)
                  if (a.mask[i])
                    constrain(node + i, value[i], sum, i);
              }
          }
        else if (a.p->type == "rigid wall")
          {
            const auto &n = a.normal;
            for (const unsigned int node : a.nodes)
              {
                double gap = 0;
                for (unsigned int i = 0; i < 3; ++i)
                  gap += (X.local_element(node + i) + d.local_element(node + i) +
                          dt_next * v.local_element(node + i) - a.point[i]) *
                         n[i];
                if (gap < 0)
                  for (unsigned int i = 0; i < 3; ++i)
                    constrain(node + i, v.local_element(node + i) - gap / dt_next * n[i], sum, i);
              }
          }
      }
    return {work_before, work_after};
  }

  double
  BoundaryConditions::apply_initial(const mesh::Vector &d, const mesh::Vector &mass, mesh::Vector &v)
  {
    const auto &X      = discretization_->reference_positions();
    double      change = 0;
    const auto  set    = [&](const unsigned int j, const double value) {
      const double m = mass.local_element(j), old = v.local_element(j);
      change += 0.5 * m * (value * value - old * old);
      v.local_element(j) = value;
    };
    for (auto &a : active_)
      {
        if (a.p->type == "fixed" || a.p->type == "velocity")
          {
            Vector<double> value(3);
            if (a.function)
              a.function->set_time(0.);
            for (const unsigned int node : a.nodes)
              {
                if (a.function)
                  a.function->vector_value(Point<3>(X.local_element(node), X.local_element(node + 1),
                                                    X.local_element(node + 2)),
                                           value);
                for (unsigned int i = 0; i < 3; ++i)
                  if (a.mask[i])
                    set(node + i, value[i]);
              }
          }
        else if (a.p->type == "rigid wall")
          for (const unsigned int node : a.nodes)
            {
              double gap = 0, vn = 0;
              for (unsigned int i = 0; i < 3; ++i)
                {
                  gap += (X.local_element(node + i) + d.local_element(node + i) - a.point[i]) * a.normal[i];
                  vn += v.local_element(node + i) * a.normal[i];
                }
              if (gap <= 1e-12 && vn < 0) // on the plane within 1 pm, moving into it
                for (unsigned int i = 0; i < 3; ++i)
                  set(node + i, v.local_element(node + i) - vn * a.normal[i]);
            }
      }
    return change;
  }

  std::vector<std::pair<std::string, int>>
  BoundaryConditions::faces() const
  {
    std::vector<std::pair<std::string, int>> out;
    for (const auto &name : names_)
      out.emplace_back(params_.at(name)->body, params_.at(name)->boundary_id);
    return out;
  }
} // namespace shard::bc
