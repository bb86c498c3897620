// SPDX-License-Identifier: LGPL-2.1-or-later
#include <shard/base/function.h>
#include <shard/base/hilbert.h>
#include <shard/base/sections.h>
#include <shard/mesh/discretization.h>
#include <shard/mesh/gmsh_check.h>

#include <deal.II/dofs/dof_tools.h>
#include <deal.II/fe/fe_q.h>
#include <deal.II/grid/grid_generator.h>
#include <deal.II/grid/grid_in.h>
#include <deal.II/grid/tria.h>
#include <deal.II/grid/tria_description.h>

#include <algorithm>
#include <chrono>
#include <limits>
#include <numeric>
#include <thread>
#include <type_traits>
#include <array>
#include <cmath>
#include <fstream>
#include <iomanip>
#include <sstream>
#include <regex>
#include <set>

namespace shard::mesh
{
  using namespace dealii;

  double
  ogive_nose_length(const double radius, const double crh, const double tip)
  {
    const double rho = 2. * radius * crh, c = rho - radius, r_m = tip * radius;
    return std::sqrt(rho * rho - (r_m + c) * (r_m + c));
  }

  double
  ogive_volume(const double radius, const double length, const double crh, const double tip)
  {
    // pi int_0^s_m (sqrt(rho^2 - s^2) - c)^2 ds + pi R^2 (L - s_m), with
    // int sqrt(rho^2 - s^2) ds = (s sqrt(rho^2 - s^2) + rho^2 asin(s / rho)) / 2.
    const double rho = 2. * radius * crh, c = rho - radius, s = ogive_nose_length(radius, crh, tip);
    const double nose = (rho * rho + c * c) * s - s * s * s / 3. -
                        c * (s * std::sqrt(rho * rho - s * s) + rho * rho * std::asin(s / rho));
    return M_PI * (nose + radius * radius * (length - s));
  }

  std::vector<double>
  graded_cell_sizes(const double lower, const double upper, const double fine_lower, const double fine_upper,
                    const double h, const double ratio)
  {
    const double a = std::max(lower, std::min(fine_lower, upper)), b = std::min(upper, std::max(fine_upper, a));
    const unsigned int n_core =
      b - a > 1e-12 * h ? std::max(1u, static_cast<unsigned int>(std::ceil((b - a) / h - 1e-6))) : 0;
    const double h0 = n_core > 0 ? (b - a) / n_core : h;
    // Cells growing from the core's size h0 over a side of length L: the fewest n with
    // h0 (r + ... + r^n) >= L, then scaled by L / sum, so no cell is larger than h0 r^k.
    const auto side = [h0, ratio](const double L) {
      std::vector<double> cells;
      if (!(L > 1e-12 * h0))
        return cells;
      double sum = 0, size = h0;
      while (sum < L * (1 - 1e-9))
        {
          size *= ratio;
          cells.push_back(size);
          sum += size;
        }
      for (auto &c : cells)
        c *= L / sum;
      return cells;
    };
    std::vector<double> sizes = side(a - lower);
    std::reverse(sizes.begin(), sizes.end());
    sizes.insert(sizes.end(), n_core, h0);
    const auto right = side(upper - b);
    sizes.insert(sizes.end(), right.begin(), right.end());
    return sizes;
  }

  namespace
  {
    /// Axis letter -> index; -1 if invalid.
    int
    axis_index(const std::string &axis)
    {
      return axis == "x" ? 0 : axis == "y" ? 1 : axis == "z" ? 2 : -1;
    }

    /// The cyclic permutation that takes x to direction @p axis: a rotation, so cell orientation
    /// is kept (rods, cylinders and ogives are meshed along x).
    Point<3>
    to_axis(const Point<3> &p, const int axis)
    {
      Point<3> q;
      for (unsigned int d = 0; d < 3; ++d)
        q[(d + axis) % 3] = p[d];
      return q;
    }

    /// The number of cells build_body() makes for a generated shape (box, rod, cylinder, ogive),
    /// computed in floating point without meshing (so that an absurd size is refused before any
    /// allocation), and the key that sets it. For gmsh the count comes from the file's scan.
    std::pair<double, std::string>
    generated_cells(const BodyParameters &b)
    {
      const std::string size_key = b.element_size > 0 ? "element size" : "refinement";
      if (b.shape == "box" || b.shape == "rod")
        {
          std::array<double, 3> lengths{{b.length, b.width, b.width}};
          std::array<double, 3> fine_lower{}, fine_upper{}, lower{}, upper{};
          if (b.shape == "box")
            {
              lower = base::parse_point(b.lower_corner), upper = base::parse_point(b.upper_corner);
              fine_lower = b.fine_lower_corner.empty() ? lower : base::parse_point(b.fine_lower_corner);
              fine_upper = b.fine_upper_corner.empty() ? upper : base::parse_point(b.fine_upper_corner);
              for (unsigned int d = 0; d < 3; ++d)
                lengths[d] = upper[d] - lower[d];
            }
          if (!(b.element_size > 0))
            return {std::pow(8., b.refinement), size_key};
          double cells = 1;
          for (unsigned int d = 0; d < 3; ++d)
            {
              const double h = b.element_size;
              if (b.shape == "box" && b.grading > 1)
                {
                  // Core of cells of size h0 <= h, then cells growing by the grading ratio r:
                  // a side of length L takes the fewest n with h0 (r + ... + r^n) >= L.
                  const double a = std::max(lower[d], std::min(fine_lower[d], upper[d]));
                  const double c = std::min(upper[d], std::max(fine_upper[d], a));
                  const double n_core = c - a > 1e-12 * h ? std::max(1., std::ceil((c - a) / h - 1e-6)) : 0.;
                  const double h0 = n_core > 0 ? (c - a) / n_core : h, r = b.grading;
                  const auto   side = [&](const double L) {
                    return L > 1e-12 * h0 ? std::ceil(std::log1p(L * (r - 1) / (h0 * r)) / std::log(r) - 1e-9) : 0.;
                  };
                  cells *= n_core + side(a - lower[d]) + side(upper[d] - c);
                }
              else
                cells *= std::max(1., std::ceil(lengths[d] / h - 1e-6));
            }
          return {cells, size_key};
        }
      if (b.shape == "cylinder" || b.shape == "ogive")
        {
          const double side0 = std::sqrt(M_PI / 5.) * b.radius;
          const double n_ref =
            b.element_size > 0 ? std::max(0., std::round(std::log2(side0 / b.element_size))) : b.refinement;
          const double axial   = b.element_size > 0 ? b.element_size : side0 / std::pow(2., n_ref);
          const double n_axial = std::max(1., std::round(b.length / (axial * std::pow(2., n_ref))));
          return {5. * n_axial * std::pow(8., n_ref), size_key};
        }
      return {0., "mesh file"};
    }

    /// The cell of @p tria (vertices through @p transform) with the smallest scaled corner
    /// Jacobian det / (longest edge)^3; returns that value (1 for a cube, <= 0 for a degenerate or
    /// inverted cell, not finite for non-finite coordinates), its index and its centre.
    struct WorstCell
    {
      double             quality = 1e300, volume = 0;
      unsigned int       index   = 0;
      dealii::Point<3>   centre;
    };

    /// Judges cell number @p index with corners @p x (deal.II's order) and keeps it if it is the
    /// worst so far.
    void
    judge_cell(WorstCell &worst, const std::array<Point<3>, 8> &x, const unsigned int index)
    {
      double longest = 0, smallest = 1e300, volume = 0;
      for (unsigned int v = 0; v < 8; ++v)
        {
          // Edges from corner v along the three reference directions, oriented +x, +y, +z.
          Tensor<1, 3> e[3];
          for (unsigned int d = 0; d < 3; ++d)
            {
              const unsigned int w = v ^ (1u << d);
              e[d]                 = (v & (1u << d)) ? x[v] - x[w] : x[w] - x[v];
              longest              = std::max(longest, e[d].norm());
            }
          const double det = e[0] * cross_product_3d(e[1], e[2]);
          smallest         = std::min(smallest, std::isfinite(det) ? det : -1e300);
          volume += det / 8;
        }
      const double quality = longest > 0 && std::isfinite(longest) ? smallest / (longest * longest * longest) : -1;
      if (!(quality >= worst.quality))
        {
          worst.quality = quality;
          worst.volume  = volume;
          worst.index   = index;
          worst.centre  = (x[0] + x[7]) / 2;
        }
    }

    WorstCell
    worst_cell(const Triangulation<3> &tria, const std::function<Point<3>(const Point<3> &)> &transform)
    {
      WorstCell    worst;
      unsigned int index = 0;
      for (const auto &cell : tria.active_cell_iterators())
        {
          std::array<Point<3>, 8> x;
          for (unsigned int v = 0; v < 8; ++v)
            x[v] = transform(cell->vertex(v));
          judge_cell(worst, x, index++);
        }
      return worst;
    }

    /// A box or a rod as GridGenerator::subdivided_hyper_rectangle (colorized) meshes it, without
    /// a Triangulation (rank 0 meshes the whole model; a Triangulation of the Hanchak slab was
    /// most of its set-up peak): the vertex coordinates per direction, computed with the same
    /// floating-point operations, so the vertices are bit-identical. The cells run x fastest,
    /// then y, then z; face ids 0..5 are x-, x+, y-, y+, z-, z+ in the body's own frame.
    struct BoxGrid
    {
      std::array<std::vector<double>, 3>         coordinate;
      std::function<Point<3>(const Point<3> &)> transform;

      unsigned int
      n(const unsigned int d) const
      {
        return static_cast<unsigned int>(coordinate[d].size()) - 1;
      }
    };

    BoxGrid
    box_grid(const BodyParameters &b)
    {
      BoxGrid    grid;
      const auto origin = base::parse_point(b.origin);
      const Point<3> o(origin[0], origin[1], origin[2]);
      const int      axis = axis_index(b.axis);
      Point<3>       p1, p2;
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
      if (b.shape == "box" && b.grading > 1 && b.element_size > 0)
        {
          // Graded box: uniform cells in the fine core, growing outside it. As deal.II: the
          // corners in increasing order (steps reversed with them), x = p1 + the sum of the steps.
          const auto fl = b.fine_lower_corner.empty() ? std::array<double, 3>{{p1[0], p1[1], p1[2]}} :
                                                        base::parse_point(b.fine_lower_corner);
          const auto fu = b.fine_upper_corner.empty() ? std::array<double, 3>{{p2[0], p2[1], p2[2]}} :
                                                        base::parse_point(b.fine_upper_corner);
          for (unsigned int d = 0; d < 3; ++d)
            {
              std::vector<double> steps = graded_cell_sizes(p1[d], p2[d], fl[d], fu[d], b.element_size, b.grading);
              double              low   = p1[d];
              if (p1[d] > p2[d])
                {
                  low = p2[d];
                  std::reverse(steps.begin(), steps.end());
                }
              double x = 0;
              grid.coordinate[d].push_back(low + x);
              for (const double h : steps)
                {
                  x += h;
                  grid.coordinate[d].push_back(low + x);
                }
            }
        }
      else
        for (unsigned int d = 0; d < 3; ++d)
          {
            // As deal.II: p1 + i (p2 - p1) / n, corners in increasing order.
            const unsigned int n = b.element_size > 0 ?
                                     std::max(1u, static_cast<unsigned int>(
                                                    std::ceil((p2[d] - p1[d]) / b.element_size - 1e-6))) :
                                     (1u << b.refinement);
            const double low = std::min(p1[d], p2[d]), high = std::max(p1[d], p2[d]);
            const double delta = (high - low) / n;
            for (unsigned int i = 0; i <= n; ++i)
              grid.coordinate[d].push_back(low + i * delta);
          }
      if (b.shape == "box")
        grid.transform = [](const Point<3> &p) { return p; };
      else
        grid.transform = [=](const Point<3> &p) { return Point<3>(to_axis(p, axis) + o); };
      return grid;
    }

    /// Meshes a cylinder, an ogive or a Gmsh body in serial; returns the vertex transform to apply
    /// afterwards (boxes and rods: box_grid()).
    std::function<Point<3>(const Point<3> &)>
    build_body(Triangulation<3> &tria, const BodyParameters &b, const base::PrmSource &source)
    {
      const std::string directory = source.directory();
      const auto origin = base::parse_point(b.origin);
      const Point<3> o(origin[0], origin[1], origin[2]);
      const int      axis = axis_index(b.axis);
      if (b.shape == "cylinder" || b.shape == "ogive")
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
          if (b.shape == "cylinder")
            return [=](const Point<3> &p) { return Point<3>(to_axis(p + Point<3>(h, 0, 0), axis) + o); };
          // Tangent ogive nose at the start face: arc radius rho = 2 R CRH, centred at distance
          // rho - R from the axis on the shoulder plane; r(s) = sqrt(rho^2 - s^2) - (rho - R) at
          // distance s from the shoulder, cut at the meplat radius r_m: nose length s_m. The
          // cross-section of the cylinder mesh at axial x < s_m is scaled by r(s_m - x) / R.
          const double R = b.radius, rho = 2. * R * b.nose_crh, c = rho - R;
          const double s_m = ogive_nose_length(R, b.nose_crh, b.nose_tip);
          return [=](const Point<3> &p) {
            Point<3> q = p + Point<3>(h, 0, 0);
            if (q[0] < s_m)
              {
                const double s = s_m - q[0], f = (std::sqrt(rho * rho - s * s) - c) / R;
                q[1] *= f;
                q[2] *= f;
              }
            return Point<3>(to_axis(q, axis) + o);
          };
        }
      // gmsh
      const std::string path =
        (!b.mesh_file.empty() && b.mesh_file[0] == '/') ? b.mesh_file : directory + b.mesh_file;
      std::ifstream in(path);
      if (!in)
        source.fail(sections::mesh + "/" + b.name + "/mesh file", b.mesh_file,
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
          source.fail(sections::mesh + "/" + b.name + "/mesh file", b.mesh_file,
                      "'" + path + "' is not a readable Gmsh mesh of hexahedra: " + base::exception_reason(e));
        }
      const double s = b.mesh_scale;
      return [=](const Point<3> &p) { return Point<3>(s * p + o); };
    }
  } // namespace

  /// One cell of the merged mesh as it travels between ranks: everything its coarse cell needs.
  struct Discretization::CellRecord
  {
    /// Coarse cell id: the index in the merged mesh.
    std::uint64_t id;
    /// Merged-mesh index of each vertex (the vertex key) and its position.
    std::uint64_t vertex[8];
    double        x[8][3];
    /// Owning rank, body (material id), boundary id of each face (internal_face_boundary_id inside).
    std::uint32_t owner, material;
    std::uint32_t boundary[6];
  };

  namespace
  {
    constexpr int tag_outcome = 8101, tag_cells = 8102;

    /// Blocking send of @p bytes bytes (checked against MPI's int count).
    void
    send_bytes(const void *data, const std::size_t bytes, const unsigned int to, const int tag, const MPI_Comm comm)
    {
      AssertThrow(bytes < static_cast<std::size_t>(std::numeric_limits<int>::max()),
                  ExcMessage("a mesh part of more than 2 GB for one rank: use more ranks"));
      const int ierr = MPI_Send(data, static_cast<int>(bytes), MPI_BYTE, to, tag, comm);
      AssertThrowMPI(ierr);
    }

    /// Receives one message of trivially copyable @p T from @p from, polling every 2 ms instead of
    /// spinning in MPI (the wait costs no CPU time while rank 0 meshes).
    template <typename T>
    std::vector<T>
    receive_quietly(const unsigned int from, const int tag, const MPI_Comm comm)
    {
      static_assert(std::is_trivially_copyable_v<T>);
      MPI_Status status;
      int        arrived = 0;
      while (true)
        {
          const int ierr = MPI_Iprobe(from, tag, comm, &arrived, &status);
          AssertThrowMPI(ierr);
          if (arrived)
            break;
          std::this_thread::sleep_for(std::chrono::milliseconds(2));
        }
      int bytes = 0;
      MPI_Get_count(&status, MPI_BYTE, &bytes);
      std::vector<T> out(bytes / sizeof(T));
      const int      ierr = MPI_Recv(out.data(), bytes, MPI_BYTE, from, tag, comm, MPI_STATUS_IGNORE);
      AssertThrowMPI(ierr);
      return out;
    }
  } // namespace

  void
  Discretization::create_from(std::vector<CellRecord> &records)
  {
    AssertThrow(!records.empty(), ExcMessage("a rank without cells: run with fewer ranks than cells"));
    std::sort(records.begin(), records.end(), [](const CellRecord &a, const CellRecord &b) { return a.id < b.id; });
    // Local vertices in key order.
    std::vector<std::pair<std::uint64_t, Point<3>>> keyed;
    keyed.reserve(8 * records.size());
    for (const auto &rec : records)
      for (unsigned int v = 0; v < 8; ++v)
        keyed.emplace_back(rec.vertex[v], Point<3>(rec.x[v][0], rec.x[v][1], rec.x[v][2]));
    std::sort(keyed.begin(), keyed.end(), [](const auto &a, const auto &b) { return a.first < b.first; });
    keyed.erase(std::unique(keyed.begin(), keyed.end(), [](const auto &a, const auto &b) { return a.first == b.first; }),
                keyed.end());
    TriangulationDescription::Description<3, 3> description;
    description.comm      = comm_;
    description.settings  = TriangulationDescription::Settings::default_setting;
    description.smoothing = dealii::Triangulation<3>::none;
    vertex_key_.resize(keyed.size());
    description.coarse_cell_vertices.resize(keyed.size());
    for (std::size_t i = 0; i < keyed.size(); ++i)
      vertex_key_[i] = keyed[i].first, description.coarse_cell_vertices[i] = keyed[i].second;
    description.cell_infos.resize(1);
    for (const auto &rec : records)
      {
        CellData<3> cell;
        for (unsigned int v = 0; v < 8; ++v)
          cell.vertices[v] = static_cast<unsigned int>(
            std::lower_bound(vertex_key_.begin(), vertex_key_.end(), rec.vertex[v]) - vertex_key_.begin());
        cell.material_id = rec.material;
        description.coarse_cells.push_back(cell);
        description.coarse_cell_index_to_coarse_cell_id.push_back(rec.id);
        TriangulationDescription::CellData<3> info;
        info.id                 = CellId(rec.id, std::vector<std::uint8_t>()).template to_binary<3>();
        info.subdomain_id       = rec.owner;
        info.level_subdomain_id = numbers::artificial_subdomain_id;
        info.manifold_id        = numbers::flat_manifold_id;
        info.manifold_line_ids.fill(numbers::flat_manifold_id);
        info.manifold_quad_ids.fill(numbers::flat_manifold_id);
        for (unsigned int f = 0; f < 6; ++f)
          if (rec.boundary[f] != numbers::internal_face_boundary_id)
            info.boundary_ids.emplace_back(f, rec.boundary[f]);
        description.cell_infos[0].push_back(info);
      }
    triangulation_.clear();
    triangulation_.create_triangulation(description);
    std::vector<CellRecord>().swap(records);
    AssertThrow(triangulation_.n_vertices() == vertex_key_.size(),
                ExcMessage("the triangulation renumbered its vertices"));
  }

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
    prm.enter_subsection(sections::mesh);
    if (declared_.empty())
      {
        prm.add_parameter("body names", body_names_text_,
                          "Comma-separated names of the bodies; each has a subsection of its own. "
                          "Names use letters, digits, '_' and '-'.");
        prm.add_parameter("particle weight", particle_weight_,
                          "Cost of one particle in units of one element for the partition over MPI ranks: "
                          "with particles at set-up and more than one rank, the cells are repartitioned with "
                          "the weight 1 per element and this value per particle (a converted cell carries "
                          "the share 1/n of each of its nodes, n the number of converted cells at the node). "
                          "0 keeps the partition by cell count. doc/performance.md, MPI scaling. Unit: 1. "
                          "Range: >= 0.",
                          Patterns::Double(0));
        prm.add_parameter("max cells", max_cells_,
                          "Upper bound on the number of cells of the whole model, checked from the bodies' "
                          "dimensions and element sizes (and the hexahedra of each .msh file) before anything is "
                          "meshed, so that a wrong size stops with a message instead of exhausting the memory. An "
                          "FE cell needs about 2.7 KB on one rank. Unit: 1. Range: >= 1.",
                          Patterns::Integer(1));
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
                          "cylinder (solid circular, along an axis), ogive (a cylinder with a tangent ogive nose "
                          "at its start face: a projectile) or gmsh (a .msh file of hexahedra).",
                          Patterns::Selection("box|rod|cylinder|ogive|gmsh"));
        prm.add_parameter("lower corner", b.lower_corner, "Box: lower corner 'x, y, z'. Unit: m.");
        prm.add_parameter("upper corner", b.upper_corner,
                          "Box: upper corner 'x, y, z'. Unit: m. Range: each > lower corner.");
        prm.add_parameter("grading", b.grading,
                          "Box: growth ratio of the element size per cell outside the fine core ('fine lower "
                          "corner', 'fine upper corner'); the core has cells of 'element size', the cells outside "
                          "grow by this factor towards the faces. 1: uniform. Needs 'element size'. Unit: 1. "
                          "Range: 1 to 2.",
                          Patterns::Double(1, 2));
        prm.add_parameter("fine lower corner", b.fine_lower_corner,
                          "Box with grading: lower corner of the fine core 'x, y, z'; empty: the box's lower "
                          "corner. Unit: m. Range: inside the box.");
        prm.add_parameter("fine upper corner", b.fine_upper_corner,
                          "Box with grading: upper corner of the fine core 'x, y, z'; empty: the box's upper "
                          "corner. Unit: m. Range: inside the box, > fine lower corner.");
        prm.add_parameter("length", b.length, "Rod and cylinder: length along the axis. Unit: m. Range: > 0.",
                          Patterns::Double(0));
        prm.add_parameter("width", b.width, "Rod: side of the square cross-section. Unit: m. Range: > 0.",
                          Patterns::Double(0));
        prm.add_parameter("radius", b.radius, "Cylinder and ogive: radius. Unit: m. Range: > 0.", Patterns::Double(0));
        prm.add_parameter("nose caliber radius", b.nose_crh,
                          "Ogive: radius of the nose arc in calibers (diameters), the CRH; 0.5 is a hemisphere. "
                          "Unit: 1. Range: >= 0.5.",
                          Patterns::Double(0));
        prm.add_parameter("nose tip", b.nose_tip,
                          "Ogive: radius of the flat tip (meplat) as a fraction of 'radius' (the mesh cannot end "
                          "in a point; the elements at the tip are this much thinner across). Unit: 1. Range: "
                          "0 < nose tip < 1.",
                          Patterns::Double(0));
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
    const std::string top = sections::mesh + "/";
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
            if (b.grading > 1)
              {
                if (!(b.element_size > 0))
                  source.fail(path + "grading", std::to_string(b.grading),
                              "needs 'element size' > 0 (the size in the fine core). Unit: 1.");
                const auto fl = b.fine_lower_corner.empty() ? l : point("fine lower corner", b.fine_lower_corner);
                const auto fu = b.fine_upper_corner.empty() ? u : point("fine upper corner", b.fine_upper_corner);
                for (unsigned int d = 0; d < 3; ++d)
                  {
                    if (!(fl[d] >= l[d] && fl[d] < u[d]))
                      source.fail(path + "fine lower corner", b.fine_lower_corner,
                                  "must lie inside the box (" + b.lower_corner + " to " + b.upper_corner +
                                    ") in every coordinate. Unit: m.");
                    if (!(fu[d] > fl[d] && fu[d] <= u[d]))
                      source.fail(path + "fine upper corner", b.fine_upper_corner,
                                  "must be > fine lower corner and inside the box (up to " + b.upper_corner +
                                    ") in every coordinate. Unit: m.");
                  }
              }
          }
        if (b.shape == "ogive")
          {
            if (!(b.radius > 0))
              source.fail(path + "radius", std::to_string(b.radius), "must be > 0. Unit: m.");
            if (!(b.nose_crh >= 0.5))
              source.fail(path + "nose caliber radius", std::to_string(b.nose_crh),
                          "must be >= 0.5 (a tangent ogive needs an arc radius of at least the radius). Unit: 1.");
            if (!(b.nose_tip > 0 && b.nose_tip < 1))
              source.fail(path + "nose tip", std::to_string(b.nose_tip), "must be > 0 and < 1. Unit: 1.");
            if (b.radius > 0 && b.nose_crh >= 0.5 && b.nose_tip > 0 && b.nose_tip < 1 &&
                !(ogive_nose_length(b.radius, b.nose_crh, b.nose_tip) < b.length))
              source.fail(path + "length", std::to_string(b.length),
                          "must be longer than the nose (" +
                            std::to_string(ogive_nose_length(b.radius, b.nose_crh, b.nose_tip)) + " m). Unit: m.");
          }
        if ((b.shape == "rod" || b.shape == "cylinder" || b.shape == "ogive") && !(b.length > 0))
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
  Discretization::prepare(const base::PrmSource &source, const std::function<SetupConversion(const Discretization &)> &conversion)
  {
    bodies_.clear();
    for (const auto &name : body_names_)
      bodies_.push_back(*declared_.at(name));
    const unsigned int n_ranks = Utilities::MPI::n_mpi_processes(comm_);
    const bool         root    = Utilities::MPI::this_mpi_process(comm_) == 0;
    // The set-up conversion rule, for the weights (on every rank: its input errors stop all).
    const SetupConversion converted =
      conversion && particle_weight_ > 0 && n_ranks > 1 ? conversion(*this) : SetupConversion();
    imbalance_by_count_ = 0;

    // Rank 0 meshes every body in serial and merges them into one mesh. Vertices are not merged
    // across bodies: bodies that touch stay separate. The other ranks wait without spinning
    // (their CPU time is not set-up work) for the outcome: an input error, or the boundary ids.
    std::vector<Point<3>>                                  vertices;
    std::vector<CellData<3>>                               cells;
    std::vector<std::array<types::boundary_id, 6>>         boundary;
    body_boundary_ids_.assign(bodies_.size(), {});
    const auto build = [&]() {
      // The model's size, before anything is meshed: every generated body's cell count.
      double total_cells = 0;
      for (const auto &b : bodies_)
        {
          auto [cells, key] = generated_cells(b);
          if (b.shape == "gmsh")
            {
              // The file's structure, line by line, before deal.II's reader sees it (a bounded read:
              // GridIn allocates by counts it reads); its hexahedra count towards the bound.
              const std::string path =
                (!b.mesh_file.empty() && b.mesh_file[0] == '/') ? b.mesh_file : source.directory() + b.mesh_file;
              std::ifstream in(path, std::ios::binary);
              if (!in)
                source.fail(sections::mesh + "/" + b.name + "/mesh file", b.mesh_file,
                            "cannot open '" + path + "'. It must be a readable Gmsh .msh file of hexahedra (path "
                            "relative to the .prm file).");
              try
                {
                  cells = static_cast<double>(check_gmsh(in).n_hexahedra);
                }
              catch (const GmshError &e)
                {
                  source.fail(sections::mesh + "/" + b.name + "/mesh file", b.mesh_file,
                              "'" + path + "' is not a readable Gmsh mesh of hexahedra: " + e.what());
                }
            }
          total_cells += cells;
          if (!(total_cells <= max_cells_))
            {
              std::ostringstream value, count, total;
              if (key == "mesh file")
                value << b.mesh_file;
              else
                value << (key == "refinement" ? static_cast<double>(b.refinement) : b.element_size);
              if (std::isfinite(cells))
                count << std::setprecision(cells < 1e15 ? 15 : 3) << cells;
              else
                count << "more than 1e308";
              total << std::setprecision(total_cells < 1e15 ? 15 : 3) << total_cells;
              source.fail(sections::mesh + "/" + b.name + "/" + key, value.str(),
                          "gives " + count.str() + " cells" +
                            (total_cells > cells ? " (the model with the bodies before it: " + total.str() + ")" : std::string()) +
                            ", more than 'B - Mesh/max cells' = " + std::to_string(max_cells_) +
                            " (about 2.7 KB of memory per cell; doc/manual/user_guide.md, Bad input). Use a larger element "
                            "size, or raise 'max cells' if the machine has the memory.");
            }
        }
      body_boundary_ids_.assign(bodies_.size(), {});
      // Degenerate elements are refused here, naming the body's key, not found as an inverted
      // element at step 1.
      const auto refuse_degenerate = [&](const BodyParameters &b, const WorstCell &worst) {
        if (!(worst.quality > 1e-9))
          {
            const std::string key = b.shape == "gmsh" ? (b.mesh_scale < 1e-100 ? "mesh scale" : "mesh file") :
                                    b.shape == "box"  ? "upper corner" :
                                    b.shape == "rod"  ? (b.width < b.length ? "width" : "length") :
                                                        "radius";
            std::ostringstream value, why;
            if (key == "mesh file" || key == "upper corner")
              value << (key == "mesh file" ? b.mesh_file : b.upper_corner);
            else
              value << (key == "mesh scale" ? b.mesh_scale : key == "width" ? b.width : key == "length" ? b.length : b.radius);
            why << std::setprecision(4) << "element " << worst.index + 1 << " of body '" << b.name << "' (centre "
                << worst.centre[0] << ", " << worst.centre[1] << ", " << worst.centre[2] << " m) is "
                << (!(worst.quality > -1e299) ? "not finite" : worst.quality > 0 ? "degenerate" : worst.volume > 0 ? "inverted at a corner" : "of zero or negative volume")
                << " (smallest corner Jacobian / longest edge^3 = " << worst.quality
                << "; a cube has 1, shard needs > 1e-9): the body's dimensions, element size"
                << (b.shape == "gmsh" ? ", the file's vertices and mesh scale" : "")
                << " must give elements of finite, positive volume.";
            source.fail(sections::mesh + "/" + b.name + "/" + key, value.str(), why.str());
          }
      };
      for (unsigned int k = 0; k < bodies_.size(); ++k)
        {
          if (bodies_[k].shape == "box" || bodies_[k].shape == "rod")
            {
              // Straight into the cell list, vertices numbered in order of first use as below
              // (the same list as through a Triangulation).
              const BoxGrid      grid = box_grid(bodies_[k]);
              const unsigned int nx = grid.n(0), ny = grid.n(1), nz = grid.n(2);
              const auto grid_point = [&](const unsigned int i, const unsigned int j, const unsigned int l) {
                return grid.transform(Point<3>(grid.coordinate[0][i], grid.coordinate[1][j], grid.coordinate[2][l]));
              };
              std::vector<std::uint64_t> number(std::uint64_t(nx + 1) * (ny + 1) * (nz + 1), ~std::uint64_t(0));
              WorstCell                  worst;
              unsigned int               index = 0;
              for (unsigned int l = 0; l < nz; ++l)
                for (unsigned int j = 0; j < ny; ++j)
                  for (unsigned int i = 0; i < nx; ++i, ++index)
                    {
                      CellData<3>             c;
                      std::array<Point<3>, 8> x;
                      for (unsigned int v = 0; v < 8; ++v)
                        {
                          const unsigned int vi = i + (v & 1), vj = j + ((v >> 1) & 1), vl = l + (v >> 2);
                          auto &n = number[(std::uint64_t(vl) * (ny + 1) + vj) * (nx + 1) + vi];
                          if (n == ~std::uint64_t(0))
                            {
                              n = vertices.size();
                              vertices.push_back(grid_point(vi, vj, vl));
                            }
                          c.vertices[v] = static_cast<unsigned int>(n);
                          x[v]          = vertices[n];
                        }
                      judge_cell(worst, x, index);
                      c.material_id = k;
                      cells.push_back(c);
                      boundary.emplace_back();
                      auto &ids = boundary.back();
                      ids.fill(numbers::internal_face_boundary_id);
                      if (i == 0)
                        ids[0] = 0;
                      if (i == nx - 1)
                        ids[1] = 1;
                      if (j == 0)
                        ids[2] = 2;
                      if (j == ny - 1)
                        ids[3] = 3;
                      if (l == 0)
                        ids[4] = 4;
                      if (l == nz - 1)
                        ids[5] = 5;
                    }
              refuse_degenerate(bodies_[k], worst);
              body_boundary_ids_[k] = {0, 1, 2, 3, 4, 5};
              continue;
            }
          dealii::Triangulation<3> tria;
          const auto       transform = build_body(tria, bodies_[k], source);
          {
            refuse_degenerate(bodies_[k], worst_cell(tria, transform));
            for (const auto &cell : tria.active_cell_iterators())
              for (const unsigned int f : cell->face_indices())
                if (cell->face(f)->at_boundary())
                  body_boundary_ids_[k].insert(cell->face(f)->boundary_id());
          }
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
                throw base::InputError(sections::mesh + "/" + bodies_[k].name +
                                       ": the mesh must consist of hexahedra only.");
              CellData<3> c;
              for (unsigned int v = 0; v < 8; ++v)
                c.vertices[v] = global_vertex(cell->vertex_index(v), cell->vertex(v));
              c.material_id = k;
              cells.push_back(c);
              boundary.emplace_back();
              boundary.back().fill(numbers::internal_face_boundary_id);
              for (const unsigned int f : cell->face_indices())
                if (cell->face(f)->at_boundary())
                  {
                    boundary.back()[f] = cell->face(f)->boundary_id();
                  }
            }
        }
    };
    // Outcome of rank 0: 0 ok (then the boundary ids), 1 input error, 2 other error (then the text).
    std::vector<char> outcome;
    if (root)
      {
        char               kind = 0;
        std::string        text;
        std::exception_ptr error;
        try
          {
            build();
          }
        catch (const base::InputError &e)
          {
            kind = 1, text = e.what(), error = std::current_exception();
          }
        catch (const std::exception &e)
          {
            kind = 2, text = base::exception_reason(e), error = std::current_exception();
          }
        outcome.push_back(kind);
        // Numbers as 4 bytes each: a count per body, then its ids.
        const auto put = [&](const std::uint32_t value) {
          const char *bytes = reinterpret_cast<const char *>(&value);
          outcome.insert(outcome.end(), bytes, bytes + 4);
        };
        if (kind == 0)
          for (const auto &ids : body_boundary_ids_)
            {
              put(ids.size());
              for (const auto id : ids)
                put(id);
            }
        else
          outcome.insert(outcome.end(), text.begin(), text.end());
        for (unsigned int r = 1; r < n_ranks; ++r)
          send_bytes(outcome.data(), outcome.size(), r, tag_outcome, comm_);
        if (error)
          std::rethrow_exception(error);
      }
    else
      {
        outcome = receive_quietly<char>(0, tag_outcome, comm_);
        if (outcome.at(0) != 0)
          {
            const std::string text(outcome.begin() + 1, outcome.end());
            if (outcome[0] == 1)
              throw base::InputError(text);
            throw std::runtime_error(text);
          }
        std::size_t k   = 1;
        const auto  get = [&]() {
          AssertThrow(k + 4 <= outcome.size(), ExcMessage("a short set-up message from rank 0"));
          std::uint32_t value;
          std::copy_n(outcome.begin() + k, 4, reinterpret_cast<char *>(&value));
          k += 4;
          return value;
        };
        for (auto &ids : body_boundary_ids_)
          {
            const std::uint32_t n = get();
            for (std::uint32_t i = 0; i < n; ++i)
              ids.insert(get());
          }
      }

    // The first partition: the cells in the order of a Hilbert curve through their centres, cut
    // into contiguous ranges of equal cell count (or of equal work, below). Rank 0 sends each rank
    // its own cells and every cell that shares a vertex with them (the ghost layer), one rank at a
    // time.
    std::vector<CellRecord> mine;
    if (root)
      {
        const std::uint64_t n_cells = cells.size();
        // Cells at each vertex (compressed rows).
        std::vector<std::uint64_t> at_vertex_start(vertices.size() + 1, 0), at_vertex;
        for (const auto &c : cells)
          for (const auto v : c.vertices)
            ++at_vertex_start[v + 1];
        for (std::size_t v = 0; v < vertices.size(); ++v)
          at_vertex_start[v + 1] += at_vertex_start[v];
        at_vertex.resize(at_vertex_start.back());
        {
          std::vector<std::uint64_t> fill(at_vertex_start.begin(), at_vertex_start.end() - 1);
          for (std::uint64_t c = 0; c < n_cells; ++c)
            for (const auto v : cells[c].vertices)
              at_vertex[fill[v]++] = c;
        }
        // order[c]: position of cell c; by_order: the cells in that order.
        std::vector<types::global_dof_index> order(n_cells);
        if (n_ranks > 1)
          {
            // Body by body (in input order), the cells along a Hilbert curve through their
            // centres, on a grid of 2^20 equal steps per direction over the body's largest extent
            // (ties by index; base::hilbert_index). Cheap: 0.05 s with the sort for the Hanchak
            // mesh (deal.II's inverse_Hilbert_space_filling_curve took 0.1 s, ordering the
            // vertex graph 3.7 s). A body stays in one piece of the order, so two bodies in
            // contact meet at the ranks' boundaries only where their parts meet (the head-on bars
            // at 4 ranks: one curve through both sent 2.2 times the contact halo).
            std::vector<std::uint64_t> key(n_cells);
            for (std::uint64_t first_cell = 0; first_cell < n_cells;)
              {
                std::uint64_t end = first_cell;
                while (end < n_cells && cells[end].material_id == cells[first_cell].material_id)
                  ++end;
                std::vector<Point<3>> centre(end - first_cell);
                Point<3>              low, high;
                for (std::uint64_t c = first_cell; c < end; ++c)
                  {
                    auto &x = centre[c - first_cell];
                    for (const auto v : cells[c].vertices)
                      x += vertices[v];
                    x /= 8.;
                    for (unsigned int d = 0; d < 3; ++d)
                      {
                        low[d]  = c == first_cell ? x[d] : std::min(low[d], x[d]);
                        high[d] = c == first_cell ? x[d] : std::max(high[d], x[d]);
                      }
                  }
                const double extent = std::max({high[0] - low[0], high[1] - low[1], high[2] - low[2], 1e-300});
                const unsigned int bits = 20;
                for (std::size_t i = 0; i < centre.size(); ++i)
                  {
                    std::array<std::uint32_t, 3> grid;
                    for (unsigned int d = 0; d < 3; ++d)
                      grid[d] = static_cast<std::uint32_t>((centre[i][d] - low[d]) / extent * ((1u << bits) - 1));
                    key[first_cell + i] = base::hilbert_index(grid, bits);
                  }
                first_cell = end;
              }
            std::vector<std::uint64_t> sorted(n_cells);
            std::iota(sorted.begin(), sorted.end(), 0);
            std::sort(sorted.begin(), sorted.end(), [&](const std::uint64_t a, const std::uint64_t b) {
              const auto ba = cells[a].material_id, bb = cells[b].material_id;
              return ba < bb || (ba == bb && (key[a] < key[b] || (key[a] == key[b] && a < b)));
            });
            for (std::uint64_t k = 0; k < n_cells; ++k)
              order[sorted[k]] = k;
          }
        else
          std::iota(order.begin(), order.end(), 0);
        std::vector<std::uint64_t> by_order(n_cells);
        for (std::uint64_t c = 0; c < n_cells; ++c)
          by_order[order[c]] = c;
        // Work of each cell in units of 1/1000 element: 1000 for an element; a cell converted
        // at set-up carries its share 1/n of each of its nodes (n converted cells at the node),
        // times the particle weight.
        std::vector<double> work(n_cells, 1000.);
        // first[r]: the first position of rank r. By count (no particles at set-up): equal
        // ranges, floor(n_cells r / n_ranks), as p4est cut its coarse cells.
        std::vector<std::uint64_t> first(n_ranks + 1);
        for (unsigned int r = 0; r <= n_ranks; ++r)
          first[r] = n_cells * r / n_ranks;
        bool weighted = false;
        if (converted)
          {
            std::vector<char> is_converted(n_cells, 0);
            bool              any = false;
            for (std::uint64_t c = 0; c < n_cells; ++c)
              {
                // The centre as deal.II computes it (the vertices summed in order, over 8), so the
                // rule decides as Conversion::prepare() does on the triangulation.
                Point<3> centre;
                for (const auto v : cells[c].vertices)
                  centre += vertices[v];
                centre /= 8.;
                is_converted[c] = converted(cells[c].material_id, {{centre[0], centre[1], centre[2]}});
                any |= is_converted[c];
              }
            if (any)
              {
                std::vector<unsigned int> n_converted(vertices.size(), 0);
                for (std::uint64_t c = 0; c < n_cells; ++c)
                  if (is_converted[c])
                    for (const auto v : cells[c].vertices)
                      ++n_converted[v];
                for (std::uint64_t c = 0; c < n_cells; ++c)
                  if (is_converted[c])
                    {
                      double particles = 0;
                      for (const auto v : cells[c].vertices)
                        particles += 1. / n_converted[v];
                      work[c] = 1000. * particle_weight_ * particles;
                    }
                // What the partition by count would carry (reported as the imbalance before).
                std::vector<double> by_count(n_ranks, 0.);
                for (unsigned int r = 0; r < n_ranks; ++r)
                  for (std::uint64_t k = first[r]; k < first[r + 1]; ++k)
                    by_count[r] += work[by_order[k]] / 1000.;
                const double total = std::accumulate(by_count.begin(), by_count.end(), 0.);
                imbalance_by_count_ = *std::max_element(by_count.begin(), by_count.end()) / (total / n_ranks);
                weighted            = true;
              }
          }
        // Weighted: the order is cut into ranges of equal work. The cell whose preceding work is
        // W goes to rank floor(W n_ranks / total), p4est's rule (integer weights of at least 1).
        if (weighted)
          {
            std::vector<std::uint64_t> weight(n_cells);
            std::uint64_t              total = 0;
            for (std::uint64_t k = 0; k < n_cells; ++k)
              total += weight[k] = std::max<std::uint64_t>(1, static_cast<std::uint64_t>(std::lround(work[by_order[k]])));
            std::fill(first.begin(), first.end(), n_cells);
            std::uint64_t before = 0;
            unsigned int  next   = 0;
            for (std::uint64_t k = 0; k < n_cells; ++k)
              {
                const auto r = std::min<std::uint64_t>(
                  n_ranks - 1, static_cast<std::uint64_t>(static_cast<long double>(before) * n_ranks / total));
                while (next <= r)
                  first[next++] = k;
                before += weight[k];
              }
          }
        std::vector<double>().swap(work);
        const auto owner = [&](const std::uint64_t c) {
          return static_cast<unsigned int>(std::upper_bound(first.begin(), first.end(), order[c]) - first.begin() - 1);
        };
        std::vector<unsigned int> stamp(n_cells, numbers::invalid_unsigned_int);
        for (unsigned int r = 0; r < n_ranks; ++r)
          {
            std::vector<std::uint64_t> local;
            for (std::uint64_t k_own = first[r]; k_own < first[r + 1]; ++k_own)
              for (const auto v : cells[by_order[k_own]].vertices)
                for (auto k = at_vertex_start[v]; k < at_vertex_start[v + 1]; ++k)
                  if (stamp[at_vertex[k]] != r)
                    {
                      stamp[at_vertex[k]] = r;
                      local.push_back(at_vertex[k]);
                    }
            std::sort(local.begin(), local.end());
            std::vector<CellRecord> records(local.size());
            for (std::size_t i = 0; i < local.size(); ++i)
              {
                auto &rec    = records[i];
                const auto &c = cells[local[i]];
                rec.id       = local[i];
                rec.owner    = owner(local[i]);
                rec.material = c.material_id;
                for (unsigned int v = 0; v < 8; ++v)
                  {
                    rec.vertex[v] = c.vertices[v];
                    for (unsigned int d = 0; d < 3; ++d)
                      rec.x[v][d] = vertices[c.vertices[v]][d];
                  }
                for (unsigned int f = 0; f < 6; ++f)
                  rec.boundary[f] = boundary[local[i]][f];
              }
            if (r == 0)
              mine = std::move(records);
            else
              send_bytes(records.data(), records.size() * sizeof(CellRecord), r, tag_cells, comm_);
          }
      }
    else
      mine = receive_quietly<CellRecord>(0, tag_cells, comm_);
    n_global_vertices_ = Utilities::MPI::broadcast(comm_, static_cast<std::uint64_t>(vertices.size()), 0);
    // The serial mesh exists on rank 0 only until here.
    std::vector<Point<3>>().swap(vertices);
    std::vector<CellData<3>>().swap(cells);
    std::vector<std::array<types::boundary_id, 6>>().swap(boundary);
    create_from(mine);
    distribute();
  }

  void
  Discretization::distribute()
  {
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

  std::string
  Discretization::boundary_ids_text(const unsigned int body) const
  {
    std::string out;
    for (const auto id : boundary_ids(body))
      out += (out.empty() ? "" : ", ") + std::to_string(id);
    return out.empty() ? std::string("none") : out;
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
