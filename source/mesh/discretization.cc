// SPDX-License-Identifier: LGPL-2.1-or-later
#include <shard/base/function.h>
#include <shard/mesh/discretization.h>

#include <deal.II/dofs/dof_tools.h>
#include <deal.II/fe/fe_q.h>
#include <deal.II/grid/grid_generator.h>
#include <deal.II/grid/grid_in.h>
#include <deal.II/grid/tria.h>

#include <cmath>
#include <fstream>
#include <regex>
#include <set>

namespace shard::mesh
{
  using namespace dealii;

  namespace
  {
    /// Axis letter -> index; -1 if invalid.
    int
    axis_index(const std::string &axis)
    {
      return axis == "x" ? 0 : axis == "y" ? 1 : axis == "z" ? 2 : -1;
    }

    /// Meshes one body in serial; returns the vertex transform to apply afterwards.
    std::function<Point<3>(const Point<3> &)>
    build_body(Triangulation<3> &tria, const BodyParameters &b, const base::PrmSource &source)
    {
      const std::string directory = source.directory();
      const auto origin = base::parse_point(b.origin);
      const Point<3> o(origin[0], origin[1], origin[2]);
      const int      axis = axis_index(b.axis);
      // Cyclic permutation x -> axis: a rotation, so cell orientation is kept.
      const auto to_axis = [axis](const Point<3> &p) {
        Point<3> q;
        for (unsigned int d = 0; d < 3; ++d)
          q[(d + axis) % 3] = p[d];
        return q;
      };
      if (b.shape == "box" || b.shape == "rod")
        {
          Point<3> p1, p2;
          if (b.shape == "box")
            {
              const auto l = base::parse_point(b.lower_corner), u = base::parse_point(b.upper_corner);
              p1 = Point<3>(l[0], l[1], l[2]);
              p2 = Point<3>(u[0], u[1], u[2]);
            }
          else
            {
              p1 = Point<3>(0, -b.width / 2, -b.width / 2);
              p2 = Point<3>(b.length, b.width / 2, b.width / 2);
            }
          std::vector<unsigned int> reps(3);
          for (unsigned int d = 0; d < 3; ++d)
            reps[d] = b.element_size > 0 ?
                        std::max(1u, static_cast<unsigned int>(
                                       std::ceil((p2[d] - p1[d]) / b.element_size - 1e-6))) :
                        (1u << b.refinement);
          GridGenerator::subdivided_hyper_rectangle(tria, reps, p1, p2, true);
          if (b.shape == "box")
            return [](const Point<3> &p) { return p; };
          return [=](const Point<3> &p) { return Point<3>(to_axis(p) + o); };
        }
      if (b.shape == "cylinder")
        {
          // The coarse cylinder has 5 cells per cross-section; after n refinements the mean
          // cell side in the cross-section is sqrt(pi R^2 / (5 4^n)) = 0.79 R / 2^n.
          const double       side0 = std::sqrt(M_PI / 5.) * b.radius;
          const unsigned int n_ref =
            b.element_size > 0 ?
              static_cast<unsigned int>(std::max(0., std::round(std::log2(side0 / b.element_size)))) :
              b.refinement;
          const double axial = b.element_size > 0 ? b.element_size : side0 / (1 << n_ref);
          const unsigned int n_axial = std::max(
            1u, static_cast<unsigned int>(std::round(b.length / (axial * (1 << n_ref)))));
          GridGenerator::subdivided_cylinder(tria, n_axial, b.radius, b.length / 2);
          tria.refine_global(n_ref);
          const double h = b.length / 2;
          return [=](const Point<3> &p) { return Point<3>(to_axis(p + Point<3>(h, 0, 0)) + o); };
        }
      // gmsh
      const std::string path =
        (!b.mesh_file.empty() && b.mesh_file[0] == '/') ? b.mesh_file : directory + b.mesh_file;
      std::ifstream in(path);
      if (!in)
        source.fail("B - Mesh/" + b.name + "/mesh file", b.mesh_file,
                    "cannot open '" + path + "'. It must be a readable Gmsh .msh file of hexahedra (path "
                    "relative to the .prm file).");
      GridIn<3> grid_in;
      grid_in.attach_triangulation(tria);
      try
        {
          grid_in.read_msh(in);
        }
      catch (const std::exception &e)
        {
          std::string what = e.what();
          what             = std::regex_replace(what, std::regex("\\s*\\n\\s*"), " ");
          source.fail("B - Mesh/" + b.name + "/mesh file", b.mesh_file,
                      "'" + path + "' is not a readable Gmsh mesh of hexahedra: " + what);
        }
      const double s = b.mesh_scale;
      return [=](const Point<3> &p) { return Point<3>(s * p + o); };
    }
  } // namespace

  Discretization::Discretization(MPI_Comm comm)
    : comm_(comm)
    , triangulation_(comm)
    , fe_(FE_Q<3>(1), 3)
    , dof_handler_(triangulation_)
  {}

  bool
  Discretization::declare_parameters(ParameterHandler &prm)
  {
    bool added = false;
    prm.enter_subsection("B - Mesh");
    if (declared_.empty())
      {
        prm.add_parameter("body names", body_names_text_,
                          "Comma-separated names of the bodies; each has a subsection of its own. "
                          "Names use letters, digits, '_' and '-'.");
        added = true;
      }
    body_names_ = base::split(body_names_text_, ',');
    for (const auto &name : body_names_)
      {
        if (declared_.count(name))
          continue;
        added     = true;
        auto &b   = *(declared_[name] = std::make_unique<BodyParameters>());
        b.name    = name;
        prm.enter_subsection(name);
        prm.add_parameter("shape", b.shape,
                          "Mesh of the body: box (lower/upper corner), rod (square bar along an axis), "
                          "cylinder (solid circular, along an axis) or gmsh (a .msh file of hexahedra).",
                          Patterns::Selection("box|rod|cylinder|gmsh"));
        prm.add_parameter("lower corner", b.lower_corner, "Box: lower corner 'x, y, z'. Unit: m.");
        prm.add_parameter("upper corner", b.upper_corner,
                          "Box: upper corner 'x, y, z'. Unit: m. Range: each > lower corner.");
        prm.add_parameter("length", b.length, "Rod and cylinder: length along the axis. Unit: m. Range: > 0.",
                          Patterns::Double(0));
        prm.add_parameter("width", b.width, "Rod: side of the square cross-section. Unit: m. Range: > 0.",
                          Patterns::Double(0));
        prm.add_parameter("radius", b.radius, "Cylinder: radius. Unit: m. Range: > 0.", Patterns::Double(0));
        prm.add_parameter("axis", b.axis, "Rod and cylinder: axis direction.", Patterns::Selection("x|y|z"));
        prm.add_parameter("origin", b.origin,
                          "Rod and cylinder: centre of the start face 'x, y, z'; gmsh: translation. Unit: m.");
        prm.add_parameter("element size", b.element_size,
                          "Target edge length of the elements; 0 uses 'refinement'. Unit: m. Range: >= 0.",
                          Patterns::Double(0));
        prm.add_parameter("refinement", b.refinement,
                          "Refinement level when 'element size' is 0: box and rod get 2^level cells per edge, "
                          "the cylinder is refined level times. Unit: 1. Range: 0 to 8.",
                          Patterns::Integer(0, 8));
        prm.add_parameter("mesh file", b.mesh_file,
                          "Gmsh: the .msh file (hexahedra; physical surface tags become boundary ids), "
                          "relative to the directory of the .prm file.");
        prm.add_parameter("mesh scale", b.mesh_scale,
                          "Gmsh: factor from the file's length unit to metres. Unit: 1. Range: > 0.",
                          Patterns::Double(0));
        prm.add_parameter("material", b.material, "Name of a material of 'C - Materials'.");
        prm.add_parameter("initial velocity", b.initial_velocity,
                          "Initial velocity: three muparser expressions of x, y, z (reference coordinates) "
                          "separated by ';'. Unit: m/s.");
        prm.leave_subsection();
      }
    prm.leave_subsection();
    return added;
  }

  void
  Discretization::check_parameters(const base::PrmSource &source) const
  {
    const std::string top = "B - Mesh/";
    base::check_names(source, top + "body names", body_names_text_, body_names_, false);
    for (const auto &name : body_names_)
      {
        const auto       &b    = *declared_.at(name);
        const std::string path = top + name + "/";
        const auto        point = [&](const std::string &key, const std::string &value) {
          try
            {
              return base::parse_point(value);
            }
          catch (const std::invalid_argument &e)
            {
              source.fail(path + key, value, std::string(e.what()) + ".");
            }
        };
        point("origin", b.origin);
        if (b.shape == "box")
          {
            const auto l = point("lower corner", b.lower_corner), u = point("upper corner", b.upper_corner);
            for (unsigned int d = 0; d < 3; ++d)
              if (!(u[d] > l[d]))
                source.fail(path + "upper corner", b.upper_corner,
                            "must be > lower corner (" + b.lower_corner + ") in every coordinate. Unit: m.");
          }
        if ((b.shape == "rod" || b.shape == "cylinder") && !(b.length > 0))
          source.fail(path + "length", std::to_string(b.length), "must be > 0. Unit: m.");
        if (b.shape == "rod" && !(b.width > 0))
          source.fail(path + "width", std::to_string(b.width), "must be > 0. Unit: m.");
        if (b.shape == "cylinder" && !(b.radius > 0))
          source.fail(path + "radius", std::to_string(b.radius), "must be > 0. Unit: m.");
        if (b.shape == "gmsh" && b.mesh_file.empty())
          source.fail(path + "mesh file", "", "a Gmsh .msh file is required when shape = gmsh.");
        if (b.shape == "gmsh")
          {
            const std::string file =
              b.mesh_file[0] == '/' ? b.mesh_file : source.directory() + b.mesh_file;
            if (!std::ifstream(file))
              source.fail(path + "mesh file", b.mesh_file,
                          "cannot open '" + file + "'. It must be a readable Gmsh .msh file of hexahedra "
                          "(path relative to the .prm file).");
          }
        if (!(b.mesh_scale > 0))
          source.fail(path + "mesh scale", std::to_string(b.mesh_scale), "must be > 0.");
        try
          {
            base::parse_vector_function(b.initial_velocity, false);
          }
        catch (const std::invalid_argument &e)
          {
            source.fail(path + "initial velocity", b.initial_velocity,
                        std::string(e.what()) + "; must be three muparser expressions of x, y, z separated by "
                                                "';'. Unit: m/s.");
          }
      }
  }

  int
  Discretization::body_index(const std::string &name) const
  {
    for (unsigned int i = 0; i < bodies_.size(); ++i)
      if (bodies_[i].name == name)
        return static_cast<int>(i);
    return -1;
  }

  void
  Discretization::prepare(const base::PrmSource &source)
  {
    bodies_.clear();
    for (const auto &name : body_names_)
      bodies_.push_back(*declared_.at(name));

    // Mesh every body in serial and merge them into one coarse mesh. Vertices are not
    // merged across bodies: bodies that touch stay separate.
    std::vector<Point<3>>    vertices;
    std::vector<CellData<3>> cells;
    SubCellData              faces;
    for (unsigned int k = 0; k < bodies_.size(); ++k)
      {
        Triangulation<3> tria;
        const auto       transform = build_body(tria, bodies_[k], source);
        std::map<unsigned int, unsigned int> vmap;
        const auto global_vertex = [&](const unsigned int v, const Point<3> &p) {
          const auto [it, inserted] = vmap.emplace(v, vertices.size());
          if (inserted)
            vertices.push_back(transform(p));
          return it->second;
        };
        for (const auto &cell : tria.active_cell_iterators())
          {
            if (cell->reference_cell() != ReferenceCells::Hexahedron)
              throw base::InputError("B - Mesh/" + bodies_[k].name +
                                     ": the mesh must consist of hexahedra only.");
            CellData<3> c;
            for (unsigned int v = 0; v < 8; ++v)
              c.vertices[v] = global_vertex(cell->vertex_index(v), cell->vertex(v));
            c.material_id = k;
            cells.push_back(c);
            for (const unsigned int f : cell->face_indices())
              if (cell->face(f)->at_boundary())
                {
                  CellData<2> q;
                  for (unsigned int v = 0; v < 4; ++v)
                    q.vertices[v] = global_vertex(cell->face(f)->vertex_index(v), cell->face(f)->vertex(v));
                  q.boundary_id = cell->face(f)->boundary_id();
                  faces.boundary_quads.push_back(q);
                }
          }
      }
    triangulation_.clear();
    triangulation_.create_triangulation(vertices, cells, faces);

    dof_handler_.distribute_dofs(fe_);
    IndexSet relevant;
    DoFTools::extract_locally_relevant_dofs(dof_handler_, relevant);
    partitioner_ = std::make_shared<Utilities::MPI::Partitioner>(dof_handler_.locally_owned_dofs(), relevant, comm_);
    reference_.reinit(partitioner_);
    for (const auto &cell : dof_handler_.active_cell_iterators())
      if (cell->is_locally_owned() || cell->is_ghost())
        for (unsigned int v = 0; v < 8; ++v)
          {
            const auto first = cell->vertex_dof_index(v, 0);
            for (unsigned int c = 0; c < 3; ++c)
              {
                const auto dof = cell->vertex_dof_index(v, c);
                AssertThrow(dof == first + c && partitioner_->in_local_range(dof) ==
                                                   partitioner_->in_local_range(first),
                            ExcMessage("the three DOFs of a vertex must be consecutive and owned by one rank"));
                reference_.local_element(partitioner_->global_to_local(dof)) = cell->vertex(v)[c];
              }
          }
  }

  std::vector<unsigned int>
  Discretization::boundary_nodes(const unsigned int body, const int boundary_id) const
  {
    std::set<unsigned int> nodes;
    for (const auto &cell : dof_handler_.active_cell_iterators())
      if ((cell->is_locally_owned() || cell->is_ghost()) && cell->material_id() == body)
        for (const unsigned int f : cell->face_indices())
          if (cell->face(f)->at_boundary() &&
              (boundary_id < 0 || cell->face(f)->boundary_id() == static_cast<types::boundary_id>(boundary_id)))
            for (unsigned int v = 0; v < 4; ++v)
              {
                const auto dof = cell->face(f)->vertex_dof_index(v, 0);
                if (partitioner_->in_local_range(dof))
                  nodes.insert(partitioner_->global_to_local(dof));
              }
    return {nodes.begin(), nodes.end()};
  }

  std::vector<std::pair<unsigned int, double>>
  Discretization::boundary_node_areas(const unsigned int body, const int boundary_id) const
  {
    Vector area(partitioner_);
    for (const auto &cell : dof_handler_.active_cell_iterators())
      if (cell->is_locally_owned() && cell->material_id() == body)
        for (const unsigned int f : cell->face_indices())
          if (cell->face(f)->at_boundary() &&
              (boundary_id < 0 || cell->face(f)->boundary_id() == static_cast<types::boundary_id>(boundary_id)))
            {
              const auto   face = cell->face(f);
              const double a    = outward_area_vector(cell, f).norm();
              for (unsigned int v = 0; v < 4; ++v)
                area.local_element(partitioner_->global_to_local(face->vertex_dof_index(v, 0))) += a / 4;
            }
    area.compress(VectorOperation::add);
    std::vector<std::pair<unsigned int, double>> out;
    for (unsigned int i = 0; i < partitioner_->locally_owned_size(); i += 3)
      if (area.local_element(i) > 0)
        out.emplace_back(i, area.local_element(i));
    return out;
  }

  std::vector<unsigned int>
  Discretization::body_nodes(const unsigned int body) const
  {
    std::set<unsigned int> nodes;
    for (const auto &cell : dof_handler_.active_cell_iterators())
      if ((cell->is_locally_owned() || cell->is_ghost()) && cell->material_id() == body)
        for (unsigned int v = 0; v < 8; ++v)
          {
            const auto dof = cell->vertex_dof_index(v, 0);
            if (partitioner_->in_local_range(dof))
              nodes.insert(partitioner_->global_to_local(dof));
          }
    return {nodes.begin(), nodes.end()};
  }

  void
  Discretization::add_ghost_dofs(const IndexSet &extra)
  {
    IndexSet ghosts = partitioner_->ghost_indices();
    ghosts.add_indices(extra);
    ghosts.subtract_set(dof_handler_.locally_owned_dofs());
    partitioner_ = std::make_shared<Utilities::MPI::Partitioner>(dof_handler_.locally_owned_dofs(), ghosts, comm_);
    Vector positions(partitioner_);
    for (unsigned int i = 0; i < partitioner_->locally_owned_size(); ++i)
      positions.local_element(i) = reference_.local_element(i);
    positions.update_ghost_values();
    reference_.reinit(partitioner_);
    reference_ = positions;
    reference_.update_ghost_values();
  }

  Tensor<1, 3>
  outward_area_vector(const DoFHandler<3>::active_cell_iterator &cell, const unsigned int f)
  {
    const auto face = cell->face(f);
    // Face vertices 0..3 in lexicographic order: diagonals 0-3 and 1-2.
    Tensor<1, 3> n = 0.5 * cross_product_3d(face->vertex(3) - face->vertex(0), face->vertex(2) - face->vertex(1));
    if (n * (face->center() - cell->center()) < 0)
      n = -n;
    return n;
  }

  std::array<Tensor<1, 3>, 4>
  nodal_area_vectors(const DoFHandler<3>::active_cell_iterator &cell, const unsigned int f)
  {
    const auto                  face = cell->face(f);
    std::array<Tensor<1, 3>, 4> a{};
    const double                g    = 0.5 / std::sqrt(3.);
    for (const double xi : {0.5 - g, 0.5 + g})
      for (const double eta : {0.5 - g, 0.5 + g})
        {
          // Lexicographic face vertices: 0 (0,0), 1 (1,0), 2 (0,1), 3 (1,1).
          const double       N[4] = {(1 - xi) * (1 - eta), xi * (1 - eta), (1 - xi) * eta, xi * eta};
          const Tensor<1, 3> dxi  = (1 - eta) * (face->vertex(1) - face->vertex(0)) + eta * (face->vertex(3) - face->vertex(2));
          const Tensor<1, 3> deta = (1 - xi) * (face->vertex(2) - face->vertex(0)) + xi * (face->vertex(3) - face->vertex(1));
          const Tensor<1, 3> n    = 0.25 * cross_product_3d(dxi, deta); // Gauss weight 1/4
          for (unsigned int v = 0; v < 4; ++v)
            a[v] += N[v] * n;
        }
    if (outward_area_vector(cell, f) * (a[0] + a[1] + a[2] + a[3]) < 0)
      for (auto &v : a)
        v = -v;
    return a;
  }
} // namespace shard::mesh
