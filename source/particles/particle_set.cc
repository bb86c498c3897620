// SPDX-License-Identifier: LGPL-2.1-or-later
#include <shard/base/region_boxes.h>
#include <shard/base/sections.h>
#include <shard/fe/hex_kernel.h>
#include <shard/particles/particle_set.h>

#include <deal.II/base/mpi.h>

#include <algorithm>
#include <numeric>
#include <cstdint>
#include <iterator>
#include <map>
#include <set>
#include <memory>
#include <unordered_map>
#include <stdexcept>
#include <cmath>
#include <iostream>
#include <sstream>

namespace shard::particles
{
  using namespace dealii;

  namespace
  {
    /// Doubles per particle in the gathered table.
    constexpr unsigned int record = 15;
    enum Field
    {
      f_id = 0,
      f_x  = 1,
      f_v  = 4,
      f_h  = 5,
      f_a  = 8,
      f_interpolating = 11,
      f_body          = 12,
      f_interface     = 13,
      f_component     = 14
    };

    /// Union-find root with path halving.
    std::uint64_t
    find_root(std::map<std::uint64_t, std::uint64_t> &parent, std::uint64_t x)
    {
      while (parent[x] != x)
        x = parent[x] = parent[parent[x]];
      return x;
    }

    /// Whether active cell @p cell is converted (cells past the end of @p converted_cells are not).
    bool
    is_converted(const std::vector<bool> &converted_cells, const unsigned int cell)
    {
      return cell < converted_cells.size() && converted_cells[cell];
    }

    /// Nodal sums over the converted cells (ParticleSet::prepare()), 3 entries per node.
    struct NodalFields
    {
      explicit NodalFields(const std::shared_ptr<const Utilities::MPI::Partitioner> &partitioner)
        : volume(partitioner)
        , spacing(partitioner)
        , area(partitioner)
        , flag(partitioner)
      {}
      /// Volume (component 0), largest incident cell extent per direction, outward area vector.
      mesh::Vector volume, spacing, area;
      /// Component 0: interpolating; 1: intact cells at the node (owned entries); 2: body + 1.
      mesh::Vector flag;
      /// 8 global node ids per owned converted cell.
      std::vector<std::uint64_t> cell_nodes;
    };

    /// Adds the faces of converted @p cell on the boundary of the converted region (the body's
    /// surface and the interface to intact cells) to the area vectors and flags the nodes of
    /// the surface faces listed in @p interpolating_faces.
    void
    add_region_faces(const DoFHandler<3>::active_cell_iterator &cell, const Utilities::MPI::Partitioner &pt,
                     const std::vector<bool> &converted_cells, const std::string &body_name,
                     const std::vector<std::pair<std::string, int>> &interpolating_faces, NodalFields &nodal)
    {
      for (const unsigned int f : cell->face_indices())
        {
          // Faces of the converted region: the body's surface and the interface to intact cells.
          const bool surface = cell->face(f)->at_boundary();
          if (!surface && is_converted(converted_cells, cell->neighbor(f)->active_cell_index()))
            continue;
          const auto face = cell->face(f);
          const auto n    = mesh::nodal_area_vectors(cell, f);
          bool       interpolating = false;
          if (surface)
            for (const auto &[b, id] : interpolating_faces)
              interpolating |= b == body_name && (id < 0 || id == static_cast<int>(face->boundary_id()));
          for (unsigned int v = 0; v < 4; ++v)
            {
              const unsigned int j = pt.global_to_local(face->vertex_dof_index(v, 0));
              for (unsigned int c = 0; c < 3; ++c)
                nodal.area.local_element(j + c) += n[v][c];
              if (interpolating)
                nodal.flag.local_element(j) = 1;
            }
        }
    }

    /// Adds converted @p cell to @p nodal: V_e / 8, the body and the cell's extent at its 8
    /// nodes, its node ids, and its faces on the boundary of the converted region.
    void
    add_converted_cell(const DoFHandler<3>::active_cell_iterator &cell, const Utilities::MPI::Partitioner &pt,
                       const std::vector<bool> &converted_cells, const std::string &body_name,
                       const std::vector<std::pair<std::string, int>> &interpolating_faces, NodalFields &nodal)
    {
      double x[8][3], B[8][3], lo[3], hi[3];
      for (unsigned int v = 0; v < 8; ++v)
        for (unsigned int c = 0; c < 3; ++c)
          x[v][c] = cell->vertex(v)[c];
      const double ve = fe::hex_volume_gradient(x, B);
      for (unsigned int c = 0; c < 3; ++c)
        {
          lo[c] = hi[c] = x[0][c];
          for (unsigned int v = 1; v < 8; ++v)
            lo[c] = std::min(lo[c], x[v][c]), hi[c] = std::max(hi[c], x[v][c]);
        }
      for (unsigned int v = 0; v < 8; ++v)
        {
          const unsigned int j = pt.global_to_local(cell->vertex_dof_index(v, 0));
          nodal.volume.local_element(j) += ve / 8;
          nodal.flag.local_element(j + 2) = cell->material_id() + 1;
          for (unsigned int c = 0; c < 3; ++c)
            nodal.spacing.local_element(j + c) = std::max(nodal.spacing.local_element(j + c), hi[c] - lo[c]);
          nodal.cell_nodes.push_back(cell->vertex_dof_index(v, 0) / 3);
        }
      add_region_faces(cell, pt, converted_cells, body_name, interpolating_faces, nodal);
    }

    /// Nodal volume, spacing, outward area vector of the converted region, the interpolating
    /// flag, the body and the number of intact (unconverted) cells, summed over cells and ranks.
    void
    sum_nodal_fields(const mesh::Discretization &discretization, const std::vector<bool> &converted_cells,
                     const std::vector<std::pair<std::string, int>> &interpolating_faces, NodalFields &nodal)
    {
      const auto &dh     = discretization.dof_handler();
      const auto &pt     = *discretization.partitioner();
      const auto &bodies = discretization.bodies();
      for (const auto &cell : dh.active_cell_iterators())
        if (cell->is_locally_owned() && !is_converted(converted_cells, cell->active_cell_index()))
          for (unsigned int v = 0; v < 8; ++v)
            {
              // flag component 1: intact cells at the node; component 2: body + 1.
              const unsigned int j = pt.global_to_local(cell->vertex_dof_index(v, 0));
              nodal.flag.local_element(j + 1) += 1;
            }
      for (const auto &cell : dh.active_cell_iterators())
        if (cell->is_locally_owned() && is_converted(converted_cells, cell->active_cell_index()))
          add_converted_cell(cell, pt, converted_cells, bodies[cell->material_id()].name, interpolating_faces, nodal);
      nodal.volume.compress(VectorOperation::add);
      nodal.area.compress(VectorOperation::add);
      nodal.spacing.compress(VectorOperation::max);
      // Components 0 and 2 are maxima, component 1 a count: the count is summed separately.
      mesh::Vector intact(discretization.partitioner());
      for (unsigned int j = 0; j < nodal.flag.locally_owned_size() + pt.n_ghost_indices(); j += 3)
        {
          intact.local_element(j)         = nodal.flag.local_element(j + 1);
          nodal.flag.local_element(j + 1) = 0;
        }
      intact.compress(VectorOperation::add);
      nodal.flag.compress(VectorOperation::max);
      for (unsigned int j = 0; j < nodal.flag.locally_owned_size(); j += 3)
        nodal.flag.local_element(j + 1) = intact.local_element(j);
    }

    /// Connected components of the converted cells (through shared nodes), by node label.
    struct Components
    {
      /// Per local entry (owned and ghost, 3 per node, component 0 used): the smallest root of
      /// this rank's own union-find among the ranks whose converted cells touch the node.
      mesh::Vector label;
      /// Union-find over the roots of all ranks that meet at shared nodes (the same on every
      /// rank; small: only components that reach a rank boundary have entries).
      std::map<std::uint64_t, std::uint64_t> joined;
      /// Index of every final root in ascending order (the same on every rank).
      std::vector<std::uint64_t> roots;

      /// Component index of the particle at local node entry @p j.
      unsigned int
      of(const unsigned int j)
      {
        auto r = static_cast<std::uint64_t>(label.local_element(j));
        if (joined.count(r))
          r = find_root(joined, r);
        return std::lower_bound(roots.begin(), roots.end(), r) - roots.begin();
      }
    };

    /// The connected components of the converted cells of all ranks (8 node ids per owned cell
    /// in @p cell_nodes). The label is the smallest global node id, so it does not depend on the
    /// partition. Each rank joins its own cells; the ranks' roots meet at the shared nodes (one
    /// min-compress of a nodal vector), and only the pairs of roots that meet there are
    /// all-gathered. @note Collective.
    Components
    connect_components(const mesh::Discretization &discretization, const std::vector<std::uint64_t> &cell_nodes)
    {
      const MPI_Comm comm = discretization.communicator();
      const auto    &pt   = *discretization.partitioner();
      Components     out;
      // This rank's union-find over its local node entries (owned and ghost, by j / 3 of the
      // node's first local entry j), the smaller global id the root: dense arrays, no map.
      const unsigned int        n_local = pt.locally_owned_size() + pt.n_ghost_indices();
      constexpr unsigned int    absent  = numbers::invalid_unsigned_int;
      std::vector<unsigned int> parent(n_local / 3 + 1, absent);
      std::vector<std::uint64_t> id(n_local / 3 + 1, 0);
      std::vector<unsigned int>  present; // the slots of the nodes of converted cells, in first-seen order
      const auto slot_of = [&](const std::uint64_t node) {
        const unsigned int j = pt.global_to_local(3 * node);
        AssertThrow(j % 3 == 0, ExcInternalError());
        const unsigned int s = j / 3;
        if (parent[s] == absent)
          {
            parent[s] = s;
            id[s]     = node;
            present.push_back(s);
          }
        return s;
      };
      const auto root_of = [&](unsigned int s) {
        while (parent[s] != s)
          s = parent[s] = parent[parent[s]];
        return s;
      };
      for (std::size_t c = 0; c < cell_nodes.size(); c += 8)
        {
          const unsigned int first = slot_of(cell_nodes[c]);
          for (unsigned int v = 1; v < 8; ++v)
            {
              const unsigned int a = root_of(first), b = root_of(slot_of(cell_nodes[c + v]));
              if (a != b)
                {
                  if (id[a] < id[b])
                    parent[b] = a;
                  else
                    parent[a] = b;
                }
            }
        }
      // Node ids are below 2^53, exact as doubles.
      constexpr double none = 1e300;
      out.label.reinit(discretization.partitioner());
      for (unsigned int j = 0; j < n_local; ++j)
        out.label.local_element(j) = none;
      for (const unsigned int s : present)
        out.label.local_element(3 * s) = std::min(out.label.local_element(3 * s), double(id[root_of(s)]));
      out.label.compress(VectorOperation::min);
      out.label.update_ghost_values();
      // Roots that meet another rank's at a shared node: pairs (larger, smaller), each once.
      std::set<std::pair<std::uint64_t, std::uint64_t>> met;
      std::vector<std::uint64_t>                        pairs, mine;
      std::sort(present.begin(), present.end(), [&](const unsigned int a, const unsigned int b) { return id[a] < id[b]; });
      for (const unsigned int s : present)
        {
          const std::uint64_t r = id[root_of(s)];
          const double        l = out.label.local_element(3 * s);
          if (l < double(r))
            met.emplace(r, static_cast<std::uint64_t>(l));
          if (id[s] == r)
            mine.push_back(r);
        }
      for (const auto &[r, l] : met)
        pairs.push_back(r), pairs.push_back(l);
      for (const auto &part : Utilities::MPI::all_gather(comm, pairs))
        for (std::size_t t = 0; t + 1 < part.size(); t += 2)
          {
            out.joined.emplace(part[t], part[t]);
            out.joined.emplace(part[t + 1], part[t + 1]);
            const auto a = find_root(out.joined, part[t]), b = find_root(out.joined, part[t + 1]);
            if (a != b)
              out.joined[std::max(a, b)] = std::min(a, b);
          }
      // Final roots: the own roots not joined to a smaller one.
      std::vector<std::uint64_t> final_roots;
      for (const auto r : mine)
        if (!out.joined.count(r) || find_root(out.joined, r) == r)
          final_roots.push_back(r);
      for (const auto &part : Utilities::MPI::all_gather(comm, final_roots))
        out.roots.insert(out.roots.end(), part.begin(), part.end());
      std::sort(out.roots.begin(), out.roots.end());
      out.roots.erase(std::unique(out.roots.begin(), out.roots.end()), out.roots.end());
      return out;
    }

    /// The table rows (`record` doubles each, Field order) of this rank's particles: the owned
    /// nodes with a volume.
    std::vector<double>
    particle_rows(const mesh::Discretization &discretization, const NodalFields &nodal, Components &components)
    {
      const auto         &pt = *discretization.partitioner();
      const auto         &X  = discretization.reference_positions();
      std::vector<double> mine;
      for (unsigned int j = 0; j < pt.locally_owned_size(); j += 3)
        if (nodal.volume.local_element(j) > 0)
          {
            const std::uint64_t id        = pt.local_to_global(j) / 3;
            const bool          interface = nodal.flag.local_element(j + 1) > 0;
            const double        row[record] = {
              double(id),
              X.local_element(j),
              X.local_element(j + 1),
              X.local_element(j + 2),
              nodal.volume.local_element(j),
              nodal.spacing.local_element(j),
              nodal.spacing.local_element(j + 1),
              nodal.spacing.local_element(j + 2),
              nodal.area.local_element(j),
              nodal.area.local_element(j + 1),
              nodal.area.local_element(j + 2),
              interface ? 1. : nodal.flag.local_element(j),
              nodal.flag.local_element(j + 2) - 1,
              interface ? 1. : 0.,
              double(components.of(j))};
            mine.insert(mine.end(), row, row + record);
          }
      return mine;
    }

    /// The particles this rank builds its stencils from: its own and those of other ranks
    /// within two support radii (the two hops of the stencils), sorted by id.
    struct ParticleTable
    {
      /// The rows of this rank and those received (rows point into them).
      std::vector<std::vector<double>> all;
      /// Row of every particle, by global id.
      std::vector<const double *> rows;
      /// 1 where the particle is owned by this rank.
      std::vector<unsigned char> owned;
    };

    /// The rows @p mine and those of other ranks within @p reach (max-norm) of this rank's
    /// particles, as one table sorted by id. Each rank all-gathers the tight boxes of its
    /// particles in the cells of a grid (base/region_boxes.h) and sends every row within
    /// @p reach of a box of another rank to that rank, point to point. @note Collective.
    ParticleTable
    halo_table(MPI_Comm comm, const std::vector<double> &mine, const double reach)
    {
      const unsigned int rank = Utilities::MPI::this_mpi_process(comm);
      const unsigned int P    = Utilities::MPI::n_mpi_processes(comm);
      ParticleTable      out;
      out.all.push_back(mine);
      if (P > 1)
        {
          const std::size_t           n = mine.size() / record;
          std::vector<base::Point>    x(n);
          for (std::size_t p = 0; p < n; ++p)
            x[p] = base::Point{{mine[record * p + f_x], mine[record * p + f_x + 1], mine[record * p + f_x + 2]}};
          const base::RegionBoxes own(x, 2. * reach);
          const auto              boxes = Utilities::MPI::all_gather(comm, own.boxes);
          std::map<unsigned int, std::vector<double>> out_rows;
          for (unsigned int r = 0; r < P; ++r)
            if (r != rank)
              {
                std::vector<double> &to = out_rows[r];
                own.for_each_near(boxes[r], reach, [&](const std::size_t p) {
                  to.insert(to.end(), &mine[record * p], &mine[record * p] + record);
                });
                if (to.empty())
                  out_rows.erase(r);
              }
          for (auto &[from, rows] : Utilities::MPI::some_to_some(comm, out_rows))
            out.all.push_back(std::move(rows));
        }
      struct Entry
      {
        const double *row;
        bool          owned;
      };
      std::vector<Entry> table;
      for (unsigned int r = 0; r < out.all.size(); ++r)
        for (std::size_t p = 0; p < out.all[r].size(); p += record)
          table.push_back({&out.all[r][p], r == 0});
      std::sort(table.begin(), table.end(), [](const Entry &a, const Entry &b) { return a.row[f_id] < b.row[f_id]; });
      for (const auto &entry : table)
        {
          out.rows.push_back(entry.row);
          out.owned.push_back(entry.owned ? 1 : 0);
        }
      return out;
    }

    /// The cloud of every particle of @p table and the owned ones, grouped by body (hence by
    /// material), in id order within a body.
    void
    fill_cloud(const ParticleTable &table, ParticleCloud &cloud, std::vector<unsigned int> &owned)
    {
      for (unsigned int p = 0; p < table.rows.size(); ++p)
        {
          const double *r = table.rows[p];
          cloud.position.push_back(Point3{{r[f_x], r[f_x + 1], r[f_x + 2]}});
          cloud.spacing.push_back(Point3{{r[f_h], r[f_h + 1], r[f_h + 2]}});
          cloud.interpolating.push_back(r[f_interpolating] > 0 ? 1 : 0);
          cloud.component.push_back(static_cast<unsigned int>(r[f_component]));
          if (table.owned[p])
            owned.push_back(p);
        }
      // Rows grouped by body (hence by material), in id order within a body.
      std::stable_sort(owned.begin(), owned.end(), [&](const unsigned int a, const unsigned int b) {
        return table.rows[a][f_body] < table.rows[b][f_body];
      });
    }
  } // namespace

  bool
  ParticleSet::declare_parameters(ParameterHandler &prm)
  {
    if (!first_declaration())
      return false;
    prm.enter_subsection(sections::particles);
    prm.add_parameter("bodies", body_names_text_,
                      "Bodies (names from 'B - Mesh/body names', comma separated) discretized by particles "
                      "instead of elements: one particle at every node of the body's hex mesh, volume = sum of "
                      "V_e/8, mass = lumped FE mass. Empty: no particles.");
    prm.add_parameter("dilation", rk_.dilation,
                      "Support radius over particle spacing (per direction: largest incident cell extent). "
                      "Unit: 1. Range: >= 1; 1.4 to 1.8 advised (larger is costlier and weakens the odd-even "
                      "control of the smoothing).",
                      Patterns::Double());
    prm.add_parameter("support", support_text_,
                      "Kernel support: box (tensor-product cubic B-spline, 27 neighbours at 1 < dilation <= 2 on a "
                      "lattice) or sphere (cubic B-spline of the scaled distance).",
                      Patterns::Selection("box|sphere"));
    prm.add_parameter("condition limit", rk_.rcond_limit,
                      "Smallest reciprocal condition number of the scaled moment matrix. A particle below it "
                      "(or with fewer than 4 neighbours) uses Shepard functions (constant consistency only) and "
                      "is reported. Unit: 1. Range: 0 to 1.",
                      Patterns::Double(0, 1));
    prm.leave_subsection();
    return true;
  }

  void
  ParticleSet::check_parameters(const base::PrmSource &source) const
  {
    if (!(rk_.dilation >= 1.0) || !std::isfinite(rk_.dilation))
      source.fail(sections::particles + "/dilation", std::to_string(rk_.dilation),
                  "must be >= 1: at 1 only the particle itself lies in its support and the moment matrix is "
                  "singular. Unit: 1. Advised: 1.4 to 1.8.");
  }

  void
  ParticleSet::prepare(mesh::Discretization &discretization, const std::vector<bool> &converted_cells,
                       const std::vector<std::pair<std::string, int>> &interpolating_faces,
                       const base::PrmSource &source)
  {
    MPI_Comm           comm = discretization.communicator();
    const unsigned int rank = Utilities::MPI::this_mpi_process(comm);
    select_bodies(discretization, source);
    unsigned long long n_cells = 0;
    for (const auto &cell : discretization.dof_handler().active_cell_iterators())
      n_cells += cell->is_locally_owned() && is_converted(converted_cells, cell->active_cell_index());
    active_ = Utilities::MPI::sum(n_cells, comm) > 0;
    clear_particles();
    if (!active())
      return;
    if (rank == 0 && !rk_.warning().empty())
      std::cerr << "warning: E - Particles: " << rk_.warning() << "\n";

    NodalFields nodal(discretization.partitioner());
    sum_nodal_fields(discretization, converted_cells, interpolating_faces, nodal);
    Components components = connect_components(discretization, nodal.cell_nodes);
    n_components_         = components.roots.size();

    // The table of this rank's particles and of those within two support radii (the stencils'
    // two hops); no rank holds all particles.
    const std::vector<double> mine = particle_rows(discretization, nodal, components);
    double                    largest_radius = 0;
    for (std::size_t p = 0; p < mine.size(); p += record)
      {
        const Point3 r = rk_.support_radius(Point3{{mine[p + f_h], mine[p + f_h + 1], mine[p + f_h + 2]}});
        largest_radius = std::max({largest_radius, r[0], r[1], r[2]});
      }
    largest_radius            = Utilities::MPI::max(largest_radius, comm);
    const ParticleTable table = halo_table(comm, mine, 2.02 * largest_radius + 1e-12);
    n_global_                 = Utilities::MPI::sum(static_cast<unsigned long long>(mine.size() / record), comm);
    table_rows_               = table.rows.size();
    ParticleCloud             cloud;
    std::vector<unsigned int> owned;
    fill_cloud(table, cloud, owned);
    try
      {
        stencils_ = build_local_stencils(cloud, owned, rk_);
      }
    catch (const std::exception &e)
      {
        throw base::InputError(std::string("E - Particles: cannot build the RK stencils: ") + e.what());
      }
    add_two_hop_ghosts(discretization, table.rows);
    set_compact_arrays(cloud, table.rows);
    set_owned_arrays(table.rows, owned);
    // Bonds broken before this rebuild (conversion, restart) stay broken: the ranks that hold
    // a particle for the first time hear of its bonds; their rows stay plain until
    // rebuild_broken_rows() (SpgForce::prepare(), after the gradient correction).
    set_targets(discretization);
    tell_targets(comm, restarting_);
    restarting_      = false;
    prepared_broken_ = broken_;
    prepared_free_   = free_;
    report_fallback(comm, cloud);
  }

  void
  ParticleSet::select_bodies(const mesh::Discretization &discretization, const base::PrmSource &source)
  {
    prepared_broken_   = broken_;
    prepared_free_     = free_;
    rk_.support        = support_text_ == "sphere" ? Support::sphere : Support::box;
    body_names_        = base::split(body_names_text_, ',');
    const auto &bodies = discretization.bodies();
    particle_body_.assign(bodies.size(), false);
    for (const auto &name : body_names_)
      {
        const int b = discretization.body_index(name);
        if (b < 0)
          source.fail(sections::particles + "/bodies", body_names_text_, "no body named '" + name + "' in 'B - Mesh/body names'.");
        particle_body_[b] = true;
      }
  }

  void
  ParticleSet::clear_particles()
  {
    stencils_ = LocalStencils();
    local_dof_.clear();
    volume_.clear();
    area_.clear();
    spacing_.clear();
    position_.clear();
    body_.clear();
    global_id_.clear();
    interface_.clear();
    component_.clear();
    n_global_ = table_rows_ = 0;
  }

  void
  ParticleSet::add_two_hop_ghosts(mesh::Discretization &discretization, const std::vector<const double *> &rows)
  {
    // Two-hop coefficients become ghosts of the one distributed vector.
    const auto &pt = *discretization.partitioner();
    IndexSet    extra(discretization.dof_handler().n_dofs());
    for (const unsigned int p : stencils_.cloud_index)
      {
        const types::global_dof_index g = 3 * static_cast<types::global_dof_index>(rows[p][f_id]);
        if (!pt.in_local_range(g))
          extra.add_range(g, g + 3);
      }
    discretization.add_ghost_dofs(extra);
    const auto &np = *discretization.partitioner();
    local_dof_.resize(stencils_.n_k);
    for (unsigned int k = 0; k < stencils_.n_k; ++k)
      local_dof_[k] = np.global_to_local(3 * static_cast<types::global_dof_index>(rows[stencils_.cloud_index[k]][f_id]));
  }

  void
  ParticleSet::set_compact_arrays(const ParticleCloud &cloud, const std::vector<const double *> &rows)
  {
    // Compact arrays for rebuilding rows after bonds break; bonds broken before this rebuild
    // (conversion during the run) stay broken.
    compact_id_.resize(stencils_.n_k);
    compact_of_.clear();
    a_by_column_ = ColumnIndex();
    g_by_column_ = ColumnIndex();
    rebuilt_a_rows_.clear();
    rebuilt_g_rows_.clear();
    changed_rows_.resize(stencils_.n_i);
    std::iota(changed_rows_.begin(), changed_rows_.end(), 0u);
    compact_position_.resize(stencils_.n_k);
    compact_radius_.resize(stencils_.n_k);
    for (unsigned int k = 0; k < stencils_.n_k; ++k)
      {
        const unsigned int p = stencils_.cloud_index[k];
        compact_id_[k]       = static_cast<unsigned long long>(rows[p][f_id]);
        compact_position_[k] = cloud.position[p];
        compact_radius_[k]   = rk_.support_radius(cloud.spacing[p]);
      }
    a_identity_.resize(stencils_.n_j);
    for (unsigned int j = 0; j < stencils_.n_j; ++j)
      a_identity_[j] = cloud.interpolating[stencils_.cloud_index[j]];
    a_intact_.assign(stencils_.a.n_entries(), 1);
    g_intact_.assign(stencils_.g.n_entries(), 1);
  }

  void
  ParticleSet::set_owned_arrays(const std::vector<const double *> &rows, const std::vector<unsigned int> &owned)
  {
    const unsigned int n = stencils_.n_i;
    volume_.resize(n);
    area_.resize(3 * n);
    spacing_.resize(n);
    position_.resize(n);
    body_.resize(n);
    global_id_.resize(n);
    interface_.resize(n);
    component_.resize(n);
    for (unsigned int i = 0; i < n; ++i)
      {
        const double *r = rows[owned[i]];
        volume_[i]      = r[f_v];
        for (unsigned int c = 0; c < 3; ++c)
          {
            area_[3 * i + c] = r[f_a + c];
            spacing_[i][c]   = r[f_h + c];
            position_[i][c]  = r[f_x + c];
          }
        body_[i]      = static_cast<unsigned int>(r[f_body]);
        global_id_[i] = static_cast<unsigned long long>(r[f_id]);
        interface_[i] = r[f_interface] > 0;
        component_[i] = static_cast<unsigned int>(r[f_component]);
        if (!(volume_[i] > 0))
          throw base::InputError("E - Particles: particle " + std::to_string(global_id_[i]) + " has no volume");
      }
  }

  void
  ParticleSet::report_fallback(MPI_Comm comm, const ParticleCloud &cloud) const
  {
    // Report particles on the Shepard fallback (ill-conditioned moment matrix).
    const unsigned int rank       = Utilities::MPI::this_mpi_process(comm);
    unsigned int       n_fallback = stencils_.fallback.size();
    for (unsigned int i = 0; i < stencils_.n_i; ++i)
      n_fallback += stencils_.a.fallback[i] && !stencils_.g.fallback[i];
    const unsigned int total_fallback = Utilities::MPI::sum(n_fallback, comm);
    if (total_fallback > 0)
      {
        std::ostringstream where;
        if (!stencils_.fallback.empty())
          {
            const Point3 &x = cloud.position[stencils_.fallback[0]];
            where << "; on rank " << rank << " the first is at (" << x[0] << ", " << x[1] << ", " << x[2] << ") m";
          }
        const auto all_where = Utilities::MPI::all_gather(comm, where.str());
        std::string text;
        for (const auto &w : all_where)
          if (text.empty() && !w.empty())
            text = w;
        if (rank == 0)
          std::cerr << "warning: E - Particles: " << total_fallback
                    << " particles have an ill-conditioned moment matrix (rcond < " << rk_.rcond_limit
                    << " or fewer than 4 neighbours) and use Shepard functions (constant consistency only)" << text
                    << "\n";
      }
  }

  void
  ParticleSet::replace_gradients(const std::vector<double> &gradients)
  {
    if (gradients.size() != stencils_.g.grad.size())
      throw std::invalid_argument("ParticleSet::replace_gradients: one gradient per stencil entry of G expected");
    std::copy(gradients.begin(), gradients.end(), stencils_.g.grad.begin());
  }

  void
  ParticleSet::set_targets(const mesh::Discretization &discretization)
  {
    constexpr unsigned int none = ~0u;
    const auto            &pt   = *discretization.partitioner();
    const unsigned int     rank = Utilities::MPI::this_mpi_process(discretization.communicator());
    const unsigned int     n_owned_dofs = pt.locally_owned_size();
    // Owner of every compact coefficient: this rank, or the rank its ghost index comes from.
    std::vector<unsigned int> ghost_end, ghost_rank;
    unsigned int              end = 0;
    for (const auto &[r, count] : pt.ghost_targets())
      {
        end += count;
        ghost_end.push_back(end);
        ghost_rank.push_back(r);
      }
    compact_owner_.resize(stencils_.n_k);
    for (unsigned int k = 0; k < stencils_.n_k; ++k)
      {
        const unsigned int l = local_dof_[k];
        compact_owner_[k]    = l < n_owned_dofs ?
                                 rank :
                                 ghost_rank[std::upper_bound(ghost_end.begin(), ghost_end.end(), l - n_owned_dofs) -
                                            ghost_end.begin()];
      }
    // Targets: the ranks that import an owned particle's DOFs, and the owners of its G row.
    std::vector<unsigned int> owned_at(n_owned_dofs / 3 + 1, none);
    for (unsigned int i = 0; i < stencils_.n_i; ++i)
      owned_at[local_dof_[i] / 3] = i;
    std::vector<std::pair<unsigned int, unsigned int>> pairs; // (owned particle, rank)
    auto         range = pt.import_indices().begin();
    unsigned int at    = range != pt.import_indices().end() ? range->first : 0;
    for (const auto &[r, count] : pt.import_targets())
      for (unsigned int left = count; left > 0;)
        {
          const unsigned int take = std::min(left, range->second - at);
          for (unsigned int l = at; l < at + take; ++l)
            if (const unsigned int i = owned_at[l / 3]; i != none && local_dof_[i] == l)
              pairs.emplace_back(i, r);
          at += take;
          left -= take;
          if (at == range->second && ++range != pt.import_indices().end())
            at = range->first;
        }
    const Stencil &g = stencils_.g;
    for (unsigned int i = 0; i < stencils_.n_i; ++i)
      for (unsigned int e = g.row_offsets[i]; e < g.row_offsets[i + 1]; ++e)
        if (compact_owner_[g.columns[e]] != rank)
          pairs.emplace_back(i, compact_owner_[g.columns[e]]);
    std::sort(pairs.begin(), pairs.end());
    pairs.erase(std::unique(pairs.begin(), pairs.end()), pairs.end());
    target_offsets_.assign(stencils_.n_i + 1, 0);
    targets_.resize(pairs.size());
    for (std::size_t t = 0; t < pairs.size(); ++t)
      {
        ++target_offsets_[pairs[t].first + 1];
        targets_[t] = pairs[t].second;
      }
    for (unsigned int i = 0; i < stencils_.n_i; ++i)
      target_offsets_[i + 1] += target_offsets_[i];
  }

  unsigned int
  ParticleSet::compact_index(const unsigned long long id)
  {
    if (compact_of_.size() != compact_id_.size())
      {
        compact_of_.clear();
        compact_of_.reserve(compact_id_.size());
        for (unsigned int k = 0; k < compact_id_.size(); ++k)
          compact_of_.emplace(compact_id_[k], k);
      }
    const auto it = compact_of_.find(id);
    return it == compact_of_.end() ? ~0u : it->second;
  }

  namespace
  {
    /// What to send to each rank: bonds and free particles. On the wire a message is the number
    /// of bonds, the two ids of each bond, then the ids of the free particles.
    using Letters = std::map<unsigned int, std::pair<std::vector<ParticleSet::Bond>, std::vector<unsigned long long>>>;

    /// Sends @p letters point to point; returns what arrived (bonds, free ids), sorted and
    /// unique; adds the bytes sent to @p bytes. Collective.
    std::pair<std::vector<ParticleSet::Bond>, std::vector<unsigned long long>>
    post(const MPI_Comm comm, const Letters &letters, double &bytes)
    {
      std::pair<std::vector<ParticleSet::Bond>, std::vector<unsigned long long>> arrived;
      if (Utilities::MPI::n_mpi_processes(comm) == 1)
        return arrived;
      std::map<unsigned int, std::vector<unsigned long long>> out;
      for (const auto &[r, letter] : letters)
        {
          auto &v = out[r];
          v.push_back(letter.first.size());
          for (const auto &[a, b] : letter.first)
            v.push_back(a), v.push_back(b);
          v.insert(v.end(), letter.second.begin(), letter.second.end());
          bytes += sizeof(unsigned long long) * v.size();
        }
      for (const auto &[from, v] : Utilities::MPI::some_to_some(comm, out))
        {
          (void)from;
          const std::size_t n = v.at(0);
          for (std::size_t t = 0; t < n; ++t)
            arrived.first.emplace_back(v[1 + 2 * t], v[2 + 2 * t]);
          arrived.second.insert(arrived.second.end(), v.begin() + 1 + 2 * n, v.end());
        }
      std::sort(arrived.first.begin(), arrived.first.end());
      arrived.first.erase(std::unique(arrived.first.begin(), arrived.first.end()), arrived.first.end());
      std::sort(arrived.second.begin(), arrived.second.end());
      arrived.second.erase(std::unique(arrived.second.begin(), arrived.second.end()), arrived.second.end());
      return arrived;
    }

    template <typename T>
    bool
    contains(const std::vector<T> &sorted, const T &x)
    {
      return std::binary_search(sorted.begin(), sorted.end(), x);
    }

    /// Merges the entries of @p list not in @p known (sorted, unique) into it; returns them,
    /// sorted.
    template <typename T>
    std::vector<T>
    merge_new(std::vector<T> list, std::vector<T> &known)
    {
      std::sort(list.begin(), list.end());
      list.erase(std::unique(list.begin(), list.end()), list.end());
      std::vector<T> fresh;
      std::set_difference(list.begin(), list.end(), known.begin(), known.end(), std::back_inserter(fresh));
      // In place, from the back: only the entries above the smallest new one move, and no second
      // copy of @p known is built. (It holds every broken bond this rank knows of, 320 000 late
      // in the showcase, and a step with new bonds merged into a copy grown entry by entry:
      // 4 % of the run.)
      std::size_t i = known.size(), j = fresh.size(), k = i + j;
      known.resize(k);
      while (j > 0)
        {
          --k;
          if (i > 0 && fresh[j - 1] < known[i - 1])
            known[k] = known[--i];
          else
            known[k] = fresh[--j];
        }
      return fresh;
    }
  } // namespace

  std::pair<std::vector<ParticleSet::Bond>, std::vector<unsigned long long>>
  ParticleSet::tell_targets(const MPI_Comm comm, const bool everyone)
  {
    const unsigned int n    = stencils_.n_i;
    const auto         owned = [&](const unsigned long long id) { return compact_index(id) < n; };
    // A restart knows only what the checkpoint says of its owned particles: all targets are new.
    if (everyone)
      told_.clear();
    // The targets each owned particle has now, and those not told before.
    std::vector<std::pair<unsigned long long, unsigned int>> now, fresh;
    for (unsigned int i = 0; i < n; ++i)
      for (auto [t, end] = targets(i); t != end; ++t)
        now.emplace_back(compact_id_[i], *t);
    std::sort(now.begin(), now.end());
    std::set_difference(now.begin(), now.end(), told_.begin(), told_.end(), std::back_inserter(fresh));
    told_.swap(now);
    if (Utilities::MPI::n_mpi_processes(comm) == 1)
      return {};
    // Bonds by particle, so that each fresh target gets its particle's bonds.
    std::map<unsigned long long, std::vector<unsigned int>> bonds_of;
    for (std::size_t t = 0; t < broken_.size(); ++t)
      for (const auto id : {broken_[t].first, broken_[t].second})
        if (owned(id))
          bonds_of[id].push_back(t);
    Letters letters;
    for (const auto &[id, r] : fresh)
      {
        if (const auto it = bonds_of.find(id); it != bonds_of.end())
          for (const unsigned int t : it->second)
            letters[r].first.push_back(broken_[t]);
        if (contains(free_, id))
          letters[r].second.push_back(id);
      }
    double     bytes = 0; // an event's traffic, not a step's: not booked (base::Traffic)
    const auto got   = post(comm, letters, bytes);
    return {merge_new(got.first, broken_), merge_new(got.second, free_)};
  }

  void
  ParticleSet::restrict_to_needed(const MPI_Comm comm)
  {
    const auto got = tell_targets(comm, true);
    apply_broken(got.first, got.second);
  }

  unsigned long long
  ParticleSet::spread_bonds(const MPI_Comm comm, const std::vector<Bond> &found, double &bytes)
  {
    const unsigned int rank = Utilities::MPI::this_mpi_process(comm);
    const unsigned int n    = stencils_.n_i;
    // Round 1: to the owners of both ends (a found bond has both in this rank's compact set).
    Letters letters;
    for (const auto &b : found)
      for (const auto id : {b.first, b.second})
        if (const unsigned int k = compact_index(id); k != ~0u && compact_owner_[k] != rank)
          letters[compact_owner_[k]].first.push_back(b);
    for (auto &[r, letter] : letters)
      {
        std::sort(letter.first.begin(), letter.first.end());
        letter.first.erase(std::unique(letter.first.begin(), letter.first.end()), letter.first.end());
      }
    std::vector<Bond> mine = post(comm, letters, bytes).first;
    mine.insert(mine.end(), found.begin(), found.end());
    std::sort(mine.begin(), mine.end());
    mine.erase(std::unique(mine.begin(), mine.end()), mine.end());
    // Round 2: each owner tells the targets of its particle of the bonds new to it.
    letters.clear();
    unsigned long long n_new = 0;
    std::vector<Bond>  learned;
    for (const auto &b : mine)
      {
        if (contains(broken_, b))
          continue;
        learned.push_back(b);
        const unsigned int ka = compact_index(b.first), kb = compact_index(b.second);
        n_new += ka < n;
        std::vector<unsigned int> to;
        for (const unsigned int k : {ka, kb})
          if (k < n)
            for (auto [t, end] = targets(k); t != end; ++t)
              to.push_back(*t);
        std::sort(to.begin(), to.end());
        to.erase(std::unique(to.begin(), to.end()), to.end());
        for (const unsigned int r : to)
          letters[r].first.push_back(b);
      }
    const auto told = post(comm, letters, bytes).first;
    learned.insert(learned.end(), told.begin(), told.end());
    break_bonds(learned);
    return n_new;
  }

  unsigned long long
  ParticleSet::spread_free(const MPI_Comm comm, const std::vector<unsigned long long> &owned_ids, double &bytes)
  {
    Letters            letters;
    unsigned long long n_new = 0;
    for (const auto id : owned_ids)
      {
        if (contains(free_, id))
          continue;
        ++n_new;
        for (auto [t, end] = targets(compact_index(id)); t != end; ++t)
          letters[*t].second.push_back(id);
      }
    std::vector<unsigned long long> ids = post(comm, letters, bytes).second;
    ids.insert(ids.end(), owned_ids.begin(), owned_ids.end());
    break_bonds({}, ids);
    return n_new;
  }

  void
  ParticleSet::mark_broken(const std::vector<Bond> &bonds, const std::vector<unsigned long long> &free_ids,
                           std::vector<unsigned int> &a_rows, std::vector<unsigned int> &g_rows)
  {
    constexpr unsigned int none = ~0u;
    const auto             find = [&](const unsigned long long id) { return compact_index(id); };
    if (!free_ids.empty())
      {
        // A free particle loses the entries of its own row and those in its column.
        for (const bool is_g : {false, true})
          {
            const Stencil &s      = is_g ? stencils_.g : stencils_.a;
            auto          &intact = is_g ? g_intact_ : a_intact_;
            auto          &rows   = is_g ? g_rows : a_rows;
            ColumnIndex   &index  = is_g ? g_by_column_ : a_by_column_;
            if (index.offsets.empty())
              index.build(s);
            const auto clear_entry = [&](const unsigned int r, const unsigned int e) {
              if (s.columns[e] != r && (is_g || !a_identity_[r]))
                {
                  intact[e] = 0;
                  rows.push_back(r);
                }
            };
            for (const unsigned long long id : free_ids)
              {
                const unsigned int k = find(id);
                if (k == none)
                  continue;
                if (k < s.n_rows())
                  for (unsigned int e = s.row_offsets[k]; e < s.row_offsets[k + 1]; ++e)
                    clear_entry(k, e);
                if (k + 1 < index.offsets.size())
                  for (unsigned int t = index.offsets[k]; t < index.offsets[k + 1]; ++t)
                    clear_entry(index.rows[t], index.entries[t]);
              }
          }
      }
    // Clears the entry of column @p column in row @p row of @p s, if there is one.
    const auto clear = [](const Stencil &s, std::vector<unsigned char> &intact, const unsigned int row,
                          const unsigned int column, std::vector<unsigned int> &rows) {
      for (unsigned int e = s.row_offsets[row]; e < s.row_offsets[row + 1]; ++e)
        if (s.columns[e] == column)
          {
            intact[e] = 0;
            rows.push_back(row);
          }
    };
    for (const auto &[p, q] : bonds)
      {
        const unsigned int cp = find(p), cq = find(q);
        if (cp == none || cq == none)
          continue;
        for (const auto &[row, column] : {std::make_pair(cp, cq), std::make_pair(cq, cp)})
          {
            if (row < stencils_.n_i && column < stencils_.n_j)
              clear(stencils_.g, g_intact_, row, column, g_rows);
            if (row < stencils_.n_j && !a_identity_[row])
              clear(stencils_.a, a_intact_, row, column, a_rows);
          }
      }
    for (auto *rows : {&a_rows, &g_rows})
      {
        std::sort(rows->begin(), rows->end());
        rows->erase(std::unique(rows->begin(), rows->end()), rows->end());
      }
  }

  void
  ParticleSet::rebuild_rows(const std::vector<unsigned int> &a_rows, const std::vector<unsigned int> &g_rows)
  {
    for (const bool is_g : {false, true})
      {
        const auto &rows   = is_g ? g_rows : a_rows;
        Stencil    &s      = is_g ? stencils_.g : stencils_.a;
        const auto &intact = is_g ? g_intact_ : a_intact_;
        if (rows.empty())
          continue;
        CsrPattern          pattern;
        std::vector<Point3> points;
        for (const unsigned int r : rows)
          {
            points.push_back(compact_position_[r]);
            for (unsigned int e = s.row_offsets[r]; e < s.row_offsets[r + 1]; ++e)
              if (intact[e])
                pattern.columns.push_back(s.columns[e]);
            pattern.row_offsets.push_back(pattern.columns.size());
          }
        // Rows that lost bonds may be far worse conditioned than any row of the intact body;
        // below the failure condition limit they use Shepard functions (doc/manual/failure.md).
        RkParameters rk  = rk_;
        rk.rcond_limit   = std::max(rk_.rcond_limit, broken_rcond_limit_);
        const Stencil fresh = build_rk_stencil(points, compact_position_, compact_radius_, pattern, rk);
        for (unsigned int k = 0; k < rows.size(); ++k)
          {
            const unsigned int r = rows[k];
            unsigned int       t = fresh.row_offsets[k];
            for (unsigned int e = s.row_offsets[r]; e < s.row_offsets[r + 1]; ++e)
              {
                const bool keep = intact[e] != 0;
                s.psi[e]        = keep ? fresh.psi[t] : 0.;
                if (is_g)
                  for (unsigned int c = 0; c < 3; ++c)
                    s.grad[3 * e + c] = keep ? fresh.grad[3 * t + c] : 0.;
                t += keep;
              }
            s.fallback[r] = fresh.fallback[k];
            s.rcond[r]    = fresh.rcond[k];
          }
      }
  }

  unsigned int
  ParticleSet::break_bonds(const std::vector<Bond> &bonds, const std::vector<unsigned long long> &free_ids)
  {
    // Only what is new: merged into the remembered lists, then marked and rebuilt.
    return apply_broken(merge_new(bonds, broken_), merge_new(free_ids, free_));
  }

  unsigned int
  ParticleSet::apply_broken(const std::vector<Bond> &new_bonds, const std::vector<unsigned long long> &new_free)
  {
    if (new_bonds.empty() && new_free.empty())
      return 0;
    std::vector<unsigned int> a_rows, g_rows;
    mark_broken(new_bonds, new_free, a_rows, g_rows);
    rebuild_rows(a_rows, g_rows);
    changed_rows_.insert(changed_rows_.end(), g_rows.begin(), g_rows.end());
    rebuilt_a_rows_.insert(rebuilt_a_rows_.end(), a_rows.begin(), a_rows.end());
    rebuilt_g_rows_.insert(rebuilt_g_rows_.end(), g_rows.begin(), g_rows.end());
    return a_rows.size() + g_rows.size();
  }

  void
  ParticleSet::rebuild_broken_rows()
  {
    if (broken_.empty() && free_.empty())
      return;
    std::vector<unsigned int> a_rows, g_rows;
    mark_broken(broken_, free_, a_rows, g_rows);
    rebuild_rows(a_rows, g_rows);
  }

  std::vector<unsigned int>
  ParticleSet::take_changed_rows()
  {
    std::vector<unsigned int> rows;
    rows.swap(changed_rows_);
    std::sort(rows.begin(), rows.end());
    rows.erase(std::unique(rows.begin(), rows.end()), rows.end());
    return rows;
  }

  std::pair<std::vector<unsigned int>, std::vector<unsigned int>>
  ParticleSet::take_rebuilt_rows()
  {
    std::pair<std::vector<unsigned int>, std::vector<unsigned int>> rows;
    rows.first.swap(rebuilt_a_rows_);
    rows.second.swap(rebuilt_g_rows_);
    for (auto *r : {&rows.first, &rows.second})
      {
        std::sort(r->begin(), r->end());
        r->erase(std::unique(r->begin(), r->end()), r->end());
      }
    return rows;
  }

  void
  ParticleSet::ColumnIndex::build(const Stencil &s)
  {
    offsets.assign(s.n_columns + 1, 0);
    for (std::size_t e = 0; e < s.n_entries(); ++e)
      ++offsets[s.columns[e] + 1];
    for (unsigned int c = 0; c < s.n_columns; ++c)
      offsets[c + 1] += offsets[c];
    rows.resize(s.n_entries());
    entries.resize(s.n_entries());
    std::vector<unsigned int> next(offsets.begin(), offsets.end() - 1);
    for (unsigned int r = 0; r < s.n_rows(); ++r)
      for (unsigned int e = s.row_offsets[r]; e < s.row_offsets[r + 1]; ++e)
        {
          const unsigned int t = next[s.columns[e]]++;
          rows[t]              = r;
          entries[t]           = e;
        }
  }

  unsigned int
  ParticleSet::intact_bonds(const unsigned int i) const
  {
    unsigned int n = 0;
    for (unsigned int e = stencils_.g.row_offsets[i]; e < stencils_.g.row_offsets[i + 1]; ++e)
      n += g_intact_[e] && stencils_.g.columns[e] != i;
    return n;
  }

  std::size_t
  ParticleSet::memory_consumption() const
  {
    const auto bytes = [](const auto &v) { return v.capacity() * sizeof(v[0]); };
    return sizeof(*this) - sizeof(stencils_) + stencils_.memory_consumption() + particle_body_.capacity() / 8 +
           bytes(local_dof_) + bytes(volume_) + bytes(area_) + bytes(spacing_) + bytes(position_) + bytes(body_) +
           bytes(global_id_) + interface_.capacity() / 8 + bytes(component_) + bytes(compact_id_) +
           bytes(compact_position_) + bytes(compact_radius_) + bytes(a_identity_) + bytes(a_intact_) +
           bytes(g_intact_) + bytes(broken_) + bytes(free_) + bytes(compact_owner_) + bytes(target_offsets_) +
           bytes(targets_) + bytes(told_);
  }
} // namespace shard::particles
