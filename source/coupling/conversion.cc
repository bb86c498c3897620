// SPDX-License-Identifier: LGPL-2.1-or-later
#include <shard/base/sections.h>
#include <shard/coupling/conversion.h>
#include <shard/fe/hex_force.h>

#include <deal.II/base/mpi.h>
#include <deal.II/grid/cell_id.h>

#include <algorithm>
#include <cmath>
#include <sstream>
#include <stdexcept>

namespace shard::coupling
{
  using namespace dealii;

  Region::Region(const RegionParameters &p, const int body)
    : body_(body)
  {
    shape_ = p.shape == "box"        ? Shape::box :
             p.shape == "cylinder"   ? Shape::cylinder :
             p.shape == "sphere"     ? Shape::sphere :
             p.shape == "half-space" ? Shape::half_space :
                                       Shape::body;
    const auto point = [](const std::string &text, const char *what) {
      try
        {
          return base::parse_point(text);
        }
      catch (const std::invalid_argument &e)
        {
          throw std::invalid_argument(std::string(what) + ": " + e.what());
        }
    };
    switch (shape_)
      {
        case Shape::box:
          a_ = point(p.lower_corner, "lower corner");
          b_ = point(p.upper_corner, "upper corner");
          for (unsigned int c = 0; c < 3; ++c)
            if (!(b_[c] > a_[c]))
              throw std::invalid_argument("upper corner: must exceed the lower corner in every coordinate");
          break;
        case Shape::sphere:
        case Shape::cylinder:
        case Shape::half_space:
          {
            a_ = point(p.centre, "centre");
            if (shape_ != Shape::sphere)
              {
                direction_     = point(p.direction, "direction");
                const double l = std::hypot(direction_[0], direction_[1], direction_[2]);
                if (!(l > 0))
                  throw std::invalid_argument("direction: must have a length > 0");
                for (auto &x : direction_)
                  x /= l;
              }
            radius_ = p.radius;
            length_ = p.length;
            if (shape_ != Shape::half_space && !(radius_ > 0))
              throw std::invalid_argument("radius: must be > 0 m");
            if (shape_ == Shape::cylinder && !(length_ > 0))
              throw std::invalid_argument("length: must be > 0 m");
            break;
          }
        case Shape::body:
          break;
      }
  }

  bool
  Region::contains(const std::array<double, 3> &x) const
  {
    const double r[3] = {x[0] - a_[0], x[1] - a_[1], x[2] - a_[2]};
    const double along = r[0] * direction_[0] + r[1] * direction_[1] + r[2] * direction_[2];
    switch (shape_)
      {
        case Shape::box:
          return x[0] >= a_[0] && x[0] <= b_[0] && x[1] >= a_[1] && x[1] <= b_[1] && x[2] >= a_[2] && x[2] <= b_[2];
        case Shape::sphere:
          return r[0] * r[0] + r[1] * r[1] + r[2] * r[2] <= radius_ * radius_;
        case Shape::cylinder:
          {
            const double off2 = r[0] * r[0] + r[1] * r[1] + r[2] * r[2] - along * along;
            return along >= 0 && along <= length_ && off2 <= radius_ * radius_;
          }
        case Shape::half_space:
          return along >= 0;
        case Shape::body:
          return true;
      }
    return false;
  }

  double
  min_corner_jacobian_ratio(const double (&x)[8][3], const double (&X)[8][3])
  {
    const auto corner = [](const double (&p)[8][3], const unsigned int v) {
      double e[3][3];
      for (unsigned int k = 0; k < 3; ++k)
        for (unsigned int c = 0; c < 3; ++c)
          e[k][c] = p[v ^ (1u << k)][c] - p[v][c];
      return e[0][0] * (e[1][1] * e[2][2] - e[1][2] * e[2][1]) - e[0][1] * (e[1][0] * e[2][2] - e[1][2] * e[2][0]) +
             e[0][2] * (e[1][0] * e[2][1] - e[1][1] * e[2][0]);
    };
    double ratio = 1e300;
    for (unsigned int v = 0; v < 8; ++v)
      ratio = std::min(ratio, corner(x, v) / corner(X, v));
    return ratio;
  }

  bool
  Conversion::declare_parameters(ParameterHandler &prm)
  {
    bool added = false;
    prm.enter_subsection(sections::conversion);
    if (!declared_main_)
      {
        declared_main_ = true;
        added          = true;
        prm.add_parameter("regions", region_names_text_,
                          "Predicted-failure regions (comma-separated names, each with a subsection of its own): "
                          "the elements whose reference centre lies in a region are converted to particles at "
                          "set-up (particles at their nodes). Empty: none.");
        prm.add_parameter("adaptive bodies", adaptive_bodies_text_,
                          "Bodies (names from 'B - Mesh/body names', comma separated) whose elements are converted "
                          "during the run when they meet one of the criteria below. Empty: no conversion during "
                          "the run.");
        prm.add_parameter("adaptive regions", adaptive_region_names_text_,
                          "Regions (comma-separated names, each with a subsection of its own, like 'regions') "
                          "that bound the conversion during the run: an element of an adaptive body converts only "
                          "when its reference centre lies in one of them. Empty: anywhere in the adaptive bodies.");
        prm.add_parameter("plastic strain", plastic_strain_,
                          "Criterion: effective plastic strain at or above this value. Unit: 1. Range: >= 0; 0 "
                          "switches the criterion off. Choose it below the failure strain of the material.",
                          Patterns::Double(0));
        prm.add_parameter("scaled damage", scaled_damage_,
                          "Criterion: K&C scaled damage delta at or above this value (1 = peak strength, 2 = "
                          "residual). Unit: 1. Range: 0 to 2; 0 switches the criterion off.",
                          Patterns::Double(0, 2));
        prm.add_parameter("minimum jacobian", min_jacobian_,
                          "Criterion: smallest corner Jacobian ratio (current over reference; 1 for a rigid "
                          "motion) at or below this value. Unit: 1. Range: 0 to 1; 0 switches the criterion off; "
                          "0.1 to 0.2 is usual.",
                          Patterns::Double(0, 1));
        prm.add_parameter("time step floor", dt_floor_,
                          "Criterion: element time step L_e / c below this value (Radioss style). Unit: s. "
                          "Range: >= 0; 0 switches the criterion off.",
                          Patterns::Double(0));
        prm.add_parameter("check interval", check_interval_,
                          "Steps between two checks of the criteria. Unit: steps. Range: >= 1.",
                          Patterns::Integer(1));
      }
    region_names_          = base::split(region_names_text_, ',');
    adaptive_region_names_ = base::split(adaptive_region_names_text_, ',');
    for (const auto &name : all_region_names())
      {
        if (declared_.count(name))
          continue;
        added   = true;
        auto &r = *(declared_[name] = std::make_unique<RegionParameters>());
        r.name  = name;
        prm.enter_subsection(name);
        prm.add_parameter("body", r.body, "Body the region applies to (a name from 'B - Mesh/body names').");
        prm.add_parameter("shape", r.shape,
                          "box (lower and upper corner), cylinder (centre of the start face, direction of the axis, "
                          "length, radius), sphere (centre, radius), half-space (a point 'centre' on the plane and "
                          "the normal 'direction' pointing into the region) or body (all elements of the body, i.e. "
                          "of its material id).",
                          Patterns::Selection("box|cylinder|sphere|half-space|body"));
        prm.add_parameter("lower corner", r.lower_corner, "Box: lower corner 'x, y, z'. Unit: m.");
        prm.add_parameter("upper corner", r.upper_corner, "Box: upper corner 'x, y, z'. Unit: m. Range: > lower.");
        prm.add_parameter("centre", r.centre,
                          "Sphere: centre; cylinder: centre of the start face; half-space: a point on the plane "
                          "'x, y, z'. Unit: m.");
        prm.add_parameter("radius", r.radius, "Sphere and cylinder: radius. Unit: m. Range: > 0.",
                          Patterns::Double(0));
        prm.add_parameter("direction", r.direction,
                          "Cylinder: axis direction; half-space: normal pointing into the region 'x, y, z'. "
                          "Unit: 1. Range: length > 0.");
        prm.add_parameter("length", r.length, "Cylinder: length along the axis. Unit: m. Range: > 0.",
                          Patterns::Double(0));
        prm.leave_subsection();
      }
    prm.leave_subsection();
    return added;
  }

  void
  Conversion::check_parameters(const base::PrmSource &source) const
  {
    base::check_names(source, sections::conversion + "/regions", region_names_text_, region_names_, true);
    base::check_names(source, sections::conversion + "/adaptive regions", adaptive_region_names_text_, adaptive_region_names_,
                      true);
    for (const auto &name : all_region_names())
      {
        const auto &r = *declared_.at(name);
        try
          {
            Region(r, 0);
          }
        catch (const std::invalid_argument &e)
          {
            const std::string what  = e.what();
            const std::string key   = what.substr(0, what.find(':'));
            const auto        value = [](const double x) {
              std::ostringstream o;
              o << x;
              return o.str();
            };
            const std::string text = key == "lower corner" ? r.lower_corner :
                                     key == "upper corner" ? r.upper_corner :
                                     key == "centre"       ? r.centre :
                                     key == "direction"    ? r.direction :
                                     key == "radius"       ? value(r.radius) :
                                                             value(r.length);
            source.fail(sections::conversion + "/" + name + "/" + key, text, what.substr(what.find(':') + 2) + ".");
          }
      }
  }

  void
  Conversion::prepare(const mesh::Discretization &discretization, const std::vector<std::string> &particle_bodies,
                      const base::PrmSource &source)
  {
    discretization_ = &discretization;
    const std::vector<Region> regions = setup_regions(discretization, particle_bodies, source);
    // A named region (of 'regions' or 'adaptive regions') with its body resolved.
    const auto resolve = [&](const std::string &name) {
      const auto &r = *declared_.at(name);
      const int   b = discretization.body_index(r.body);
      if (b < 0)
        source.fail(sections::conversion + "/" + name + "/body", r.body, "no body named '" + r.body + "' in 'B - Mesh/body names'.");
      return Region(r, b);
    };
    std::vector<Region> adaptive_regions;
    for (const auto &name : adaptive_region_names_)
      adaptive_regions.push_back(resolve(name));
    std::vector<bool> adaptive_body(discretization.bodies().size(), false);
    adaptive_bodies_.clear();
    for (const auto &name : base::split(adaptive_bodies_text_, ','))
      {
        const int b = discretization.body_index(name);
        if (b < 0)
          source.fail(sections::conversion + "/adaptive bodies", adaptive_bodies_text_,
                      "no body named '" + name + "' in 'B - Mesh/body names'.");
        adaptive_body[b] = true;
        adaptive_bodies_.push_back(b);
      }
    if (adaptive() && plastic_strain_ == 0 && scaled_damage_ == 0 && min_jacobian_ == 0 && dt_floor_ == 0)
      source.fail(sections::conversion + "/adaptive bodies", adaptive_bodies_text_,
                  "names bodies for conversion during the run, but every criterion is 0 (off): set 'plastic "
                  "strain', 'scaled damage', 'minimum jacobian' or 'time step floor'.");

    const auto &tria = discretization.triangulation();
    converted_.assign(tria.n_active_cells(), false);
    adaptive_cell_.assign(tria.n_active_cells(), false);
    unsigned long long owned = 0;
    for (const auto &cell : tria.active_cell_iterators())
      if (!cell->is_artificial())
        {
          const auto                  c    = cell->center();
          const std::array<double, 3> x    = {{c[0], c[1], c[2]}};
          const int                   body = static_cast<int>(cell->material_id());
          bool                        in   = false;
          for (const auto &r : regions)
            in |= r.body() == body && r.contains(x);
          converted_[cell->active_cell_index()] = in;
          owned += in && cell->is_locally_owned();
          // Adaptive: a cell of an adaptive body, inside one of the adaptive regions if any.
          bool adaptive = adaptive_body[body] && adaptive_regions.empty();
          for (const auto &r : adaptive_regions)
            adaptive |= adaptive_body[body] && r.body() == body && r.contains(x);
          adaptive_cell_[cell->active_cell_index()] = adaptive;
        }
    n_converted_ = Utilities::MPI::sum(owned, discretization.communicator());
    n_events_    = 0;
  }

  std::vector<Region>
  Conversion::setup_regions(const mesh::Discretization &discretization, const std::vector<std::string> &particle_bodies,
                            const base::PrmSource &source) const
  {
    std::vector<Region> regions;
    for (const auto &name : particle_bodies)
      {
        const int b = discretization.body_index(name);
        if (b < 0)
          source.fail(sections::particles + "/bodies", name, "no body named '" + name + "' in 'B - Mesh/body names'.");
        RegionParameters whole;
        whole.shape = "body";
        regions.emplace_back(whole, b);
      }
    for (const auto &name : region_names_)
      {
        const auto &r = *declared_.at(name);
        const int   b = discretization.body_index(r.body);
        if (b < 0)
          source.fail(sections::conversion + "/" + name + "/body", r.body, "no body named '" + r.body + "' in 'B - Mesh/body names'.");
        regions.emplace_back(r, b);
      }
    return regions;
  }

  std::function<bool(unsigned int, const std::array<double, 3> &)>
  Conversion::converted_at_setup(const mesh::Discretization &discretization,
                                 const std::vector<std::string> &particle_bodies, const base::PrmSource &source) const
  {
    auto regions = setup_regions(discretization, particle_bodies, source);
    return [regions = std::move(regions)](const unsigned int body, const std::array<double, 3> &x) {
      bool in = false;
      for (const auto &r : regions)
        in |= r.body() == static_cast<int>(body) && r.contains(x);
      return in;
    };
  }

  std::vector<std::string>
  Conversion::all_region_names() const
  {
    std::vector<std::string> names(region_names_);
    names.insert(names.end(), adaptive_region_names_.begin(), adaptive_region_names_.end());
    return names;
  }

  std::vector<unsigned int>
  Conversion::candidates(const fe::HexForce &hex, const mesh::Vector &d) const
  {
    std::vector<unsigned int> out;
    const auto               &X = discretization_->reference_positions();
    for (unsigned int e = 0; e < hex.n_local_elements(); ++e)
      {
        if (!adaptive_cell_[hex.cell_index(e)])
          continue;
        bool convert = false;
        if (plastic_strain_ > 0)
          convert |= hex.state_value(e, materials::slot::plastic_strain) >= plastic_strain_;
        if (scaled_damage_ > 0)
          convert |= hex.state_value(e, "scaled damage") >= scaled_damage_;
        if (dt_floor_ > 0)
          convert |= hex.element_stable_dt(e) < dt_floor_;
        if (min_jacobian_ > 0 && !convert)
          {
            double x[8][3], X0[8][3];
            for (unsigned int a = 0; a < 8; ++a)
              for (unsigned int c = 0; c < 3; ++c)
                {
                  const unsigned int j = hex.node(e, a) + c;
                  X0[a][c]             = X.local_element(j);
                  x[a][c]              = X0[a][c] + d.local_element(j);
                }
            convert |= min_corner_jacobian_ratio(x, X0) <= min_jacobian_;
          }
        if (convert)
          out.push_back(e);
      }
    return out;
  }

  unsigned long long
  Conversion::add_cells(const std::vector<unsigned int> &cells)
  {
    const auto &tria = discretization_->triangulation();
    const auto  comm = discretization_->communicator();
    std::vector<unsigned int> sorted(cells);
    std::sort(sorted.begin(), sorted.end());
    std::vector<types::coarse_cell_id> mine;
    for (const auto &cell : tria.active_cell_iterators())
      if (cell->is_locally_owned() && std::binary_search(sorted.begin(), sorted.end(), cell->active_cell_index()))
        mine.push_back(cell->id().get_coarse_cell_id());
    std::vector<types::coarse_cell_id> all;
    for (const auto &part : Utilities::MPI::all_gather(comm, mine))
      all.insert(all.end(), part.begin(), part.end());
    std::sort(all.begin(), all.end());
    if (all.empty())
      return 0;
    unsigned long long added_here = 0;
    for (const auto &cell : tria.active_cell_iterators())
      if (!cell->is_artificial() && std::binary_search(all.begin(), all.end(), cell->id().get_coarse_cell_id()) &&
          !converted_[cell->active_cell_index()])
        {
          converted_[cell->active_cell_index()] = true;
          added_here += cell->is_locally_owned();
        }
    const unsigned long long added = Utilities::MPI::sum(added_here, comm);
    n_converted_ += added;
    ++n_events_;
    return added;
  }
} // namespace shard::coupling
