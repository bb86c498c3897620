// SPDX-License-Identifier: LGPL-2.1-or-later
#include <shard/base/function.h>
#include <shard/base/sections.h>
#include <shard/bc/boundary_conditions.h>

#include <deal.II/base/mpi.h>

#include <algorithm>
#include <cmath>
#include <iterator>
#include <limits>
#include <set>
#include <sstream>

namespace shard::bc
{
  using namespace dealii;

  bool
  BoundaryConditions::declare_parameters(ParameterHandler &prm)
  {
    bool added = false;
    prm.enter_subsection(sections::boundary_conditions);
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
                          "frictionless plane through 'wall point' with 'wall normal' towards the body; blast: "
                          "Kingery-Bulmash blast pressure of a charge ('charge mass', 'tnt equivalence', "
                          "'charge position', 'burst') on the reference faces, with the angle of incidence "
                          "(doc/manual/blast.md).",
                          Patterns::Selection("fixed|velocity|traction|rigid wall|blast"));
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
        prm.add_parameter("charge mass", c.charge_mass,
                          "Blast: mass of the explosive charge; times 'tnt equivalence' it gives the TNT mass W of "
                          "the Kingery-Bulmash fits. Unit: kg. Range: > 0.",
                          Patterns::Double());
        prm.add_parameter("tnt equivalence", c.tnt_equivalence,
                          "Blast: TNT equivalence factor of the explosive (1 for TNT; e.g. about 1.2 to 1.4 for C-4, "
                          "depending on the quantity matched). Unit: 1. Range: > 0.",
                          Patterns::Double());
        prm.add_parameter("charge position", c.charge_position,
                          "Blast: centre 'x, y, z' of the charge; for a hemispherical surface burst the point "
                          "on the ground at the charge. The scaled distance Z = R / W^(1/3) of every loaded face "
                          "centre must lie in the Kingery-Bulmash range (hemispherical 0.0674 to 39.67, "
                          "spherical 0.0532 to 39.67 m/kg^(1/3)). Unit: m.");
        prm.add_parameter("burst", c.burst,
                          "Blast: hemispherical (charge on the ground, UFC 3-340-02 Fig. 2-15) or spherical "
                          "(free-air burst, Fig. 2-7).",
                          Patterns::Selection("hemispherical|spherical"));
        prm.leave_subsection();
      }
    prm.leave_subsection();
    return added;
  }

  void
  BoundaryConditions::check_parameters(const base::PrmSource &source) const
  {
    const std::string top = sections::boundary_conditions + "/";
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
        if (c.type == "blast")
          {
            const auto text = [](const double x) {
              std::ostringstream s;
              s << x;
              return s.str();
            };
            if (!(c.charge_mass > 0) || !std::isfinite(c.charge_mass))
              source.fail(path + "charge mass", text(c.charge_mass), "must be > 0. Unit: kg.");
            if (!(c.tnt_equivalence > 0) || !std::isfinite(c.tnt_equivalence))
              source.fail(path + "tnt equivalence", text(c.tnt_equivalence), "must be > 0. Unit: 1.");
            try
              {
                base::parse_point(c.charge_position);
              }
            catch (const std::invalid_argument &e)
              {
                source.fail(path + "charge position", c.charge_position, std::string(e.what()) + ". Unit: m.");
              }
            try
              {
                parse_burst(c.burst);
              }
            catch (const std::invalid_argument &e)
              {
                source.fail(path + "burst", c.burst, "must be hemispherical or spherical.");
              }
          }
      }
  }

  void
  BoundaryConditions::prepare(const mesh::Discretization &discretization, const base::PrmSource &source)
  {
    discretization_ = &discretization;
    active_.clear();
    for (const auto &name : names_)
      {
        const auto &c    = *params_.at(name);
        const int   body = discretization.body_index(c.body);
        const std::string path = sections::boundary_conditions + "/" + name + "/";
        if (body < 0)
          source.fail(path + "body", c.body, "no such body in 'B - Mesh/body names'.");
        if (c.boundary_id >= 0 && !discretization.boundary_ids(body).count(static_cast<unsigned int>(c.boundary_id)))
          source.fail(path + "boundary id", std::to_string(c.boundary_id),
                      "body '" + c.body + "' has no faces with this id; its boundary ids are " +
                        discretization.boundary_ids_text(body) + " (or -1: every boundary face).");
        Active a;
        a.p = &c;
        if (c.type == "traction")
          a.areas = discretization.boundary_node_areas(body, c.boundary_id);
        else if (c.type == "blast")
          prepare_blast(discretization, body, source, a);
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
    // Two kinematic conditions that set the same component of the same node contradict each
    // other: the later one wins at every kick, and the reactions of both are booked as boundary
    // work, so the energy balance is wrong there (two fixed conditions only repeat each other).
    {
      const auto &X = discretization.reference_positions();
      for (unsigned int i = 0; i < active_.size(); ++i)
        for (unsigned int j = i + 1; j < active_.size(); ++j)
          {
            const auto &a = *active_[i].p, &b = *active_[j].p;
            const bool  kinematic =
              (a.type == "fixed" || a.type == "velocity") && (b.type == "fixed" || b.type == "velocity");
            if (!kinematic || (a.type == "fixed" && b.type == "fixed") || a.body != b.body)
              continue;
            std::string shared;
            for (unsigned int d = 0; d < 3; ++d)
              if (active_[i].mask[d] && active_[j].mask[d])
                shared += (shared.empty() ? "" : ", ") + std::string(1, "xyz"[d]);
            if (shared.empty())
              continue;
            // Owned nodes of both (sorted lists), counted over all ranks; one of them for the message.
            std::vector<unsigned int> common;
            std::set_intersection(active_[i].nodes.begin(), active_[i].nodes.end(), active_[j].nodes.begin(),
                                  active_[j].nodes.end(), std::back_inserter(common));
            std::ostringstream where;
            if (!common.empty())
              where << "(" << X.local_element(common[0]) << ", " << X.local_element(common[0] + 1) << ", "
                    << X.local_element(common[0] + 2) << ") m";
            const auto n = Utilities::MPI::sum(static_cast<unsigned long long>(common.size()),
                                               discretization.communicator());
            if (n == 0)
              continue;
            std::string at;
            for (const auto &w : Utilities::MPI::all_gather(discretization.communicator(), where.str()))
              if (at.empty())
                at = w;
            source.fail(sections::boundary_conditions + "/" + b.name + "/type", b.type,
                        "conflicts with condition '" + a.name + "' (" + a.type + "): both set the " + shared +
                          " velocity of " + std::to_string(n) + " node(s) of body '" + a.body + "' (boundary ids " +
                          std::to_string(a.boundary_id) + " and " + std::to_string(b.boundary_id) +
                          "; one at " + at + "). Give each component of a node one kinematic condition.");
          }
    }
    // Prescribed velocities and tractions must be finite where they act, at t = 0 (later times
    // are checked by the energy balance of every history row).
    {
      std::string local;
      for (auto &a : active_)
        if (a.function && local.empty())
          {
            const auto where = base::non_finite_at(*a.function, reference_points(a), 0.);
            if (!where.empty())
              local = a.p->name + "\n" + where;
          }
      for (const auto &m : Utilities::MPI::all_gather(discretization.communicator(), local))
        if (!m.empty())
          {
            const auto name = m.substr(0, m.find('\n'));
            source.fail(sections::boundary_conditions + "/" + name + "/function", params_.at(name)->function,
                        "is not finite: " + m.substr(m.find('\n') + 1) + ".");
          }
    }
    // Walls act last so that they only change the normal velocity left by the other conditions.
    std::stable_partition(active_.begin(), active_.end(),
                          [](const Active &a) { return a.p->type != "rigid wall"; });
  }

  void
  BoundaryConditions::prepare_blast(const mesh::Discretization &discretization, const unsigned int body,
                                    const base::PrmSource &source, Active &a)
  {
    const auto       &c    = *a.p;
    const std::string path = sections::boundary_conditions + "/" + c.name + "/";
    const BlastCharge charge(c.charge_mass * c.tnt_equivalence, base::parse_point(c.charge_position),
                             parse_burst(c.burst));
    const auto       &partitioner = *discretization.partitioner();
    // Every face with an owned node: such a face belongs to an owned or a ghost cell, so each
    // rank sees all the faces of its nodes and needs no exchange of forces.
    double z_lo = std::numeric_limits<double>::max(), z_hi = 0;
    unsigned int n_faces = 0;
    std::vector<std::pair<std::array<double, 3>, std::array<double, 3>>> points; // centre, area vector
    for (const auto &cell : discretization.dof_handler().active_cell_iterators())
      if ((cell->is_locally_owned() || cell->is_ghost()) && cell->material_id() == body)
        for (const unsigned int f : cell->face_indices())
          if (cell->face(f)->at_boundary() &&
              (c.boundary_id < 0 || cell->face(f)->boundary_id() == static_cast<types::boundary_id>(c.boundary_id)))
            {
              Active::BlastFace face;
              for (unsigned int v = 0; v < 4; ++v)
                {
                  const auto dof = cell->face(f)->vertex_dof_index(v, 0);
                  if (partitioner.in_local_range(dof))
                    face.nodes.push_back(partitioner.global_to_local(dof));
                }
              if (face.nodes.empty())
                continue;
              const auto A = mesh::outward_area_vector(cell, f);
              const auto x = cell->face(f)->center();
              face.area    = {{A[0], A[1], A[2]}};
              const std::array<double, 3> centre{{x[0], x[1], x[2]}};
              const double                z = charge.scaled_distance(centre);
              z_lo                          = std::min(z_lo, z);
              z_hi                          = std::max(z_hi, z);
              points.emplace_back(centre, face.area);
              ++n_faces;
              a.blast_faces.push_back(std::move(face));
            }
    const auto comm = discretization.communicator();
    z_lo            = Utilities::MPI::min(z_lo, comm);
    z_hi            = Utilities::MPI::max(z_hi, comm);
    if (Utilities::MPI::sum(n_faces, comm) == 0)
      throw base::InputError(path + "boundary id = " + std::to_string(c.boundary_id) + ": body '" + c.body +
                             "' has no boundary faces with this id.");
    const Burst burst      = parse_burst(c.burst);
    const double lo = kb_z_min(burst), hi = kb_z_max(burst);
    if (z_lo < lo * (1 - 1e-12) || z_hi > hi * (1 + 1e-12))
      {
        std::ostringstream s;
        s << "the loaded faces of body '" << c.body << "' (boundary id " << c.boundary_id
          << ") lie at scaled distances Z = " << z_lo << " to " << z_hi << " m/kg^(1/3) from the charge of "
          << charge.mass() << " kg TNT; the Kingery-Bulmash " << c.burst << " fits hold for " << lo
          << " <= Z <= " << hi << " m/kg^(1/3) (Z = R / W^(1/3); move the charge or change 'charge mass').";
        source.fail(path + "charge position", c.charge_position, s.str());
      }
    for (unsigned int k = 0; k < points.size(); ++k)
      a.blast_faces[k].load = charge.at(points[k].first, points[k].second);
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
    for (const auto &a : active_)
      add_forces(a, t, f);
  }

  template <typename Visit>
  void
  BoundaryConditions::for_each_nodal_force(const Active &a, const double t, Visit &&visit) const
  {
    if (a.p->type == "blast")
      // Reference-face pressure, one point per face: -p(x_f, t) A_f / 4 at each node.
      for (const auto &face : a.blast_faces)
        {
          const double p = face.load.pressure(t);
          if (p == 0)
            continue;
          for (const unsigned int node : face.nodes)
            for (unsigned int i = 0; i < 3; ++i)
              visit(node, i, -(0.25 * p * face.area[i]));
        }
    else if (a.p->type == "traction")
      {
        const auto &X = discretization_->reference_positions();
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
              visit(node, i, value[i] * area);
          }
      }
  }

  std::array<double, 3>
  BoundaryConditions::applied_force(const std::string &name, const double t) const
  {
    std::array<double, 3> sum{{0, 0, 0}};
    for (const auto &a : active_)
      if (a.p->name == name)
        for_each_nodal_force(a, t, [&](unsigned int, const unsigned int i, const double value) { sum[i] += value; });
    return sum;
  }

  void
  BoundaryConditions::add_forces(const Active &a, const double t, mesh::Vector &f) const
  {
    for_each_nodal_force(a, t, [&](const unsigned int node, const unsigned int i, const double value) {
      f.local_element(node + i) += value;
    });
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

  std::vector<Point<3>>
  BoundaryConditions::reference_points(const Active &a) const
  {
    const auto           &X = discretization_->reference_positions();
    std::vector<Point<3>> points;
    const auto            add = [&](const unsigned int node) {
      points.emplace_back(X.local_element(node), X.local_element(node + 1), X.local_element(node + 2));
    };
    if (a.p->type == "traction")
      for (const auto &[node, area] : a.areas)
        add(node);
    else
      for (const unsigned int node : a.nodes)
        add(node);
    return points;
  }

  std::string
  BoundaryConditions::non_finite_report(const double t) const
  {
    for (const auto &a : active_)
      if (a.function)
        {
          if (const auto where = base::non_finite_at(*a.function, reference_points(a), t); !where.empty())
            return sections::boundary_conditions + "/" + a.p->name + "/function = " + a.p->function + " is not finite: " + where;
        }
    return "";
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
