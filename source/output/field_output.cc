// SPDX-License-Identifier: LGPL-2.1-or-later
#include <shard/base/sections.h>
#include <shard/materials/material.h>
#include <shard/output/field_output.h>

#include <deal.II/base/hdf5.h>
#include <deal.II/base/mpi.h>
#include <deal.II/fe/mapping_q1_eulerian.h>
#include <deal.II/numerics/data_out.h>

#include <algorithm>
#include <cmath>
#include <iterator>
#include <limits>
#include <unordered_map>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <sstream>

#include <unistd.h>

namespace shard::output
{
  using namespace dealii;

  namespace
  {
    /// A record of the mesh or particle series is a VTU one (.pvtu file) or an XDMF grid (XML).
    bool
    is_vtu_record(const std::string &entry)
    {
      return entry.size() > 5 && entry.compare(entry.size() - 5, 5, ".pvtu") == 0;
    }

    /// The XDMF time series of the HDF5 records (the VTU records belong to the PVD file).
    std::string
    xdmf_series(const std::vector<std::pair<double, std::string>> &records)
    {
      std::string x = "<?xml version=\"1.0\" ?>\n<!DOCTYPE Xdmf SYSTEM \"Xdmf.dtd\" []>\n<Xdmf Version=\"2.0\">\n"
                      "  <Domain>\n    <Grid Name=\"CellTime\" GridType=\"Collection\" CollectionType=\"Temporal\">\n";
      for (const auto &record : records)
        if (!is_vtu_record(record.second))
          x += record.second;
      return x + "    </Grid>\n  </Domain>\n</Xdmf>\n";
    }

    /// One field of an HDF5 grid: name, components (1 or 3) and n x components values.
    struct Hdf5Field
    {
      std::string        name;
      unsigned int       components;
      std::vector<float> values;
    };

    /**
     * The part of one grid a rank writes: its nodes (reference + displacement, 3 doubles each),
     * its cells (nodes_per_cell rank-local node numbers each) and the node and cell fields.
     */
    struct Hdf5Grid
    {
      std::vector<double>       nodes;
      unsigned int              nodes_per_cell = 1;
      std::vector<unsigned int> cells;
      std::vector<Hdf5Field>    node_fields, cell_fields;
    };

    /// Writes @p n x @p components values of @p data at row @p offset of a new dataset of @p rows rows.
    template <typename T>
    void
    write_rows(HDF5::File &file, const std::string &name, const std::vector<T> &data, const unsigned int components,
               const unsigned long long offset, const unsigned long long rows)
    {
      std::vector<hsize_t> dimensions{hsize_t(rows)};
      if (components > 1)
        dimensions.push_back(components);
      auto set = file.create_dataset<T>(name, dimensions);
      if (data.empty())
        set.template write_none<T>(); // collective: every rank takes part
      else
        {
          std::vector<hsize_t> at{hsize_t(offset)}, count{hsize_t(data.size() / components)};
          if (components > 1)
            at.push_back(0), count.push_back(components);
          set.write_hyperslab(data, at, count);
        }
    }

    /**
     * Writes @p grid of every rank into one HDF5 file @p directory / @p file (parallel HDF5, each
     * rank its rows: nodes and cells in rank order; a node shared by two ranks is written by
     * both) and returns, on every rank, the XDMF grid that describes it: geometry in double,
     * fields in single precision (as the .vtu files), cell fields with Center="Cell".
     * @p topology is the XDMF topology type ("Hexahedron" or "Polyvertex"). @note Collective.
     */
    std::string
    write_hdf5(const Hdf5Grid &grid, const std::string &directory, const std::string &file, const double time,
               const std::string &topology, const MPI_Comm comm)
    {
      const unsigned long long n_nodes = grid.nodes.size() / 3, n_cells = grid.cells.size() / grid.nodes_per_cell;
      unsigned long long       local[2] = {n_nodes, n_cells}, first[2] = {0, 0}, total[2] = {0, 0};
      MPI_Exscan(local, first, 2, MPI_UNSIGNED_LONG_LONG, MPI_SUM, comm);
      MPI_Allreduce(local, total, 2, MPI_UNSIGNED_LONG_LONG, MPI_SUM, comm);
      if (Utilities::MPI::this_mpi_process(comm) == 0)
        first[0] = first[1] = 0; // MPI_Exscan leaves rank 0's result undefined
      AssertThrow(total[0] < std::numeric_limits<unsigned int>::max(),
                  ExcMessage("HDF5 field output: more than 2^32 nodes (the connectivity is 32 bit)."));
      std::vector<unsigned int> cells(grid.cells);
      for (auto &c : cells)
        c += static_cast<unsigned int>(first[0]);

      {
        HDF5::File h5(directory + "/" + file, HDF5::File::FileAccessMode::create, comm);
        write_rows(h5, "nodes", grid.nodes, 3, first[0], total[0]);
        write_rows(h5, "cells", cells, grid.nodes_per_cell, first[1], total[1]);
        for (const auto &f : grid.node_fields)
          write_rows(h5, f.name, f.values, f.components, first[0], total[0]);
        for (const auto &f : grid.cell_fields)
          write_rows(h5, f.name, f.values, f.components, first[1], total[1]);
      } // closed here: the XDMF index names the file only after it is complete

      const auto item = [&](const std::string &name, const unsigned long long rows, const unsigned int components,
                            const char *type, const unsigned int precision) {
        std::ostringstream x;
        x << "          <DataItem Dimensions=\"" << rows << (components > 1 ? " " + std::to_string(components) : "")
          << "\" NumberType=\"" << type << "\" Precision=\"" << precision << "\" Format=\"HDF\">" << file << ":/"
          << name << "</DataItem>\n";
        return x.str();
      };
      std::ostringstream x;
      x.precision(17);
      x << "      <Grid Name=\"" << file << "\" GridType=\"Uniform\">\n        <Time Value=\"" << time << "\"/>\n"
        << "        <Geometry GeometryType=\"XYZ\">\n"
        << item("nodes", total[0], 3, "Float", 8) << "        </Geometry>\n"
        << "        <Topology TopologyType=\"" << topology << "\" NumberOfElements=\"" << total[1] << "\""
        << (grid.nodes_per_cell == 1 ? " NodesPerElement=\"1\"" : "") << ">\n"
        << item("cells", total[1], grid.nodes_per_cell, "UInt", 4) << "        </Topology>\n";
      const auto attributes = [&](const std::vector<Hdf5Field> &fields, const char *centre,
                                  const unsigned long long rows) {
        for (const auto &f : fields)
          x << "        <Attribute Name=\"" << f.name << "\" AttributeType=\""
            << (f.components == 3 ? "Vector" : "Scalar") << "\" Center=\"" << centre << "\">\n"
            << item(f.name, rows, f.components, "Float", 4) << "        </Attribute>\n";
      };
      attributes(grid.node_fields, "Node", total[0]);
      attributes(grid.cell_fields, "Cell", total[1]);
      x << "      </Grid>\n";
      return x.str();
    }
  } // namespace


  bool
  FieldOutput::declare_parameters(ParameterHandler &prm)
  {
    if (!first_declaration())
      return false;
    prm.enter_subsection(sections::output);
    prm.add_parameter("directory", directory_,
                      "Output directory (created if missing); relative paths are relative to the "
                      "working directory.");
    prm.add_parameter("interval", interval_,
                      "Simulated time between field outputs (PVTU or HDF5, see format); 0 writes the first and "
                      "last step only. "
                      "Unit: s. Range: >= 0.",
                      Patterns::Double(0));
    prm.add_parameter("format", format_,
                      "File format of the fields: vtu (one .vtu per rank per output, solution.pvd and "
                      "particles.pvd), hdf5 (one .h5 file per output written by all ranks through parallel "
                      "HDF5, indexed by solution.xdmf and particles.xdmf; ParaView opens the .xdmf with its "
                      "XDMF reader), or auto (hdf5 from 17 ranks on, vtu below).",
                      Patterns::Selection("auto|vtu|hdf5"));
    prm.add_parameter("fields", fields_,
                      "Whether the run writes field files (of the mesh and the particles, in the given format) at "
                      "all; "
                      "false keeps history.csv, summary.json and the fragment tables only (benchmarks, "
                      "sweeps).");
    prm.add_parameter("history interval", history_interval_,
                      "Steps between rows of history.csv. Unit: 1. Range: >= 1.", Patterns::Integer(1));
    prm.add_parameter("progress interval", progress_interval_,
                      "Wall-clock time between progress lines on stderr; 0 disables them. Unit: s. Range: >= 0.",
                      Patterns::Double(0));
    prm.add_parameter("fragment plots", fragment_plots_,
                      "With particles: at the end write fragments.png (cumulative mass, speed and cone-angle "
                      "distributions of the debris in fragment_statistics.csv, dust apart) with "
                      "contrib/utilities/plot_fragments.py (/usr/bin/python3 and matplotlib; a failure only "
                      "prints a warning).");
    prm.add_parameter("dust particles", dust_particles_,
                      "With particles: debris fragments (every fragment but the heaviest of its body) of fewer "
                      "than this many nodes (particles; FE nodes count too) are dust, reported apart in "
                      "fragment_statistics.csv, summary.json and fragments.png; 1: no dust. Unit: 1. Range: >= 1.",
                      Patterns::Integer(1));
    prm.add_parameter("debris axis", debris_axis_,
                      "With particles: direction 'x, y, z' about which the cone angle of the fragment "
                      "velocities is measured (the angle between a fragment's velocity and this axis), e.g. "
                      "the direction of the impact. Unit: 1. Range: finite, length > 0 (normalised).");
    prm.leave_subsection();
    return true;
  }

  void
  FieldOutput::check_parameters(const base::PrmSource &source) const
  {
    if (directory_.empty())
      source.fail(sections::output + "/directory", "", "must not be empty.");
    std::array<double, 3> a{};
    try
      {
        a = base::parse_point(debris_axis_);
      }
    catch (const std::invalid_argument &e)
      {
        source.fail(sections::output + "/debris axis", debris_axis_, std::string(e.what()) + ".");
      }
    if (!(std::hypot(a[0], a[1], a[2]) > 0))
      source.fail(sections::output + "/debris axis", debris_axis_, "must have a length > 0.");
  }

  std::string
  FieldOutput::resolve_format(const std::string &format, const unsigned int n_ranks)
  {
    if (format == "auto")
      return n_ranks > 16 ? "hdf5" : "vtu";
    return format;
  }

  std::array<double, 3>
  FieldOutput::debris_axis() const
  {
    auto         a = base::parse_point(debris_axis_);
    const double l = std::hypot(a[0], a[1], a[2]);
    for (auto &x : a)
      x /= l;
    return a;
  }

  void
  FieldOutput::prepare(const mesh::Discretization &discretization, const fe::HexForce &hex,
                       const particles::SpgForce &particles)
  {
    discretization_ = &discretization;
    hex_            = &hex;
    particles_      = &particles;
    records_.clear();
    particle_records_.clear();
    resolved_format_ = resolve_format(format_, Utilities::MPI::n_mpi_processes(discretization.communicator()));
    // Only checked here: a run that stops before its first step leaves no trace (create_directory()).
    std::string problem;
    if (Utilities::MPI::this_mpi_process(discretization.communicator()) == 0)
      {
        std::error_code       ec;
        std::filesystem::path p = std::filesystem::absolute(directory_, ec);
        while (!ec && !std::filesystem::exists(p, ec) && p.has_parent_path() && p != p.parent_path())
          p = p.parent_path();
        if (ec || !std::filesystem::is_directory(p, ec))
          problem = "'" + p.string() + "' is not a directory";
        else if (::access(p.c_str(), W_OK | X_OK) != 0)
          problem = "'" + p.string() + "' is not writable";
      }
    problem = Utilities::MPI::broadcast(discretization.communicator(), problem, 0);
    if (!problem.empty())
      throw base::InputError(sections::output + "/directory = " + directory_ + ": cannot create the directory (" + problem +
                             ").");
  }

  void
  FieldOutput::create_directory() const
  {
    std::string problem;
    if (Utilities::MPI::this_mpi_process(discretization_->communicator()) == 0)
      {
        std::error_code ec;
        std::filesystem::create_directories(directory_, ec);
        if (ec || !std::filesystem::is_directory(directory_))
          problem = ec.message();
      }
    problem = Utilities::MPI::broadcast(discretization_->communicator(), problem, 0);
    if (!problem.empty())
      throw std::runtime_error(sections::output + "/directory = " + directory_ + ": cannot create the directory (" + problem +
                               ").");
  }

  void
  FieldOutput::write(const double time, const mesh::Vector &d, const mesh::Vector &v)
  {
    if (!fields_)
      return;
    const auto        &dh   = discretization_->dof_handler();
    const auto         comm = discretization_->communicator();
    const unsigned int n    = discretization_->triangulation().n_active_cells();
    Vector<float> sxx(n), syy(n), szz(n), syz(n), sxz(n), sxy(n), vm(n), eps(n), failed(n), body(n), rank(n),
      converted(n);
    const float this_rank = Utilities::MPI::this_mpi_process(comm);
    // Cells without an element are converted to particles (their stress lives at the particles).
    for (const auto &cell : dh.active_cell_iterators())
      if (cell->is_locally_owned())
        {
          converted[cell->active_cell_index()] = hex_->element_of_cell(cell->active_cell_index()) < 0;
          body[cell->active_cell_index()]      = cell->material_id();
          rank[cell->active_cell_index()]      = this_rank;
        }
    for (unsigned int e = 0; e < hex_->n_local_elements(); ++e)
      {
        const unsigned int c = hex_->cell_index(e);
        const double      *s = hex_->stress(e);
        sxx[c]               = s[0];
        syy[c]               = s[1];
        szz[c]               = s[2];
        syz[c]               = s[3];
        sxz[c]               = s[4];
        sxy[c]               = s[5];
        vm[c]                = materials::von_mises_stress(s);
        eps[c]               = hex_->state_value(e, materials::slot::plastic_strain);
        failed[c]            = hex_->state_value(e, materials::slot::failed);
        body[c]              = hex_->body(e);
        rank[c]              = this_rank;
      }

    const std::string stem = "solution_" + Utilities::int_to_string(records_.size(), 4);
    const std::pair<Vector<float> *, const char *> cell_fields[] = {
      {&sxx, "stress_xx"}, {&syy, "stress_yy"}, {&szz, "stress_zz"}, {&syz, "stress_yz"},
      {&sxz, "stress_xz"}, {&sxy, "stress_xy"}, {&vm, "von_mises_stress"}, {&eps, "plastic_strain"},
      {&failed, "failed"}, {&body, "material"}, {&rank, "mpi_rank"}, {&converted, "converted"}};
    if (resolved_format_ == "hdf5")
      {
        // Nodes of the owned cells, each once per rank, on the deformed mesh; cell fields per cell.
        Hdf5Grid                                   grid;
        std::unordered_map<unsigned int, unsigned> node_of_vertex;
        Hdf5Field displacement{"displacement", 3, {}}, velocity{"velocity", 3, {}};
        grid.nodes_per_cell = 8;
        for (const auto &[field, name] : cell_fields)
          grid.cell_fields.push_back({name, 1, {}});
        // deal.II numbers the vertices of a hexahedron lexicographically, XDMF (as VTK) around
        // the bottom face, then the top face.
        constexpr unsigned int xdmf_order[8] = {0, 1, 3, 2, 4, 5, 7, 6};
        for (const auto &cell : dh.active_cell_iterators())
          if (cell->is_locally_owned())
            {
              for (const unsigned int vertex : xdmf_order)
                {
                  const auto [at, added] =
                    node_of_vertex.emplace(cell->vertex_index(vertex), unsigned(node_of_vertex.size()));
                  grid.cells.push_back(at->second);
                  if (!added)
                    continue;
                  for (unsigned int c = 0; c < 3; ++c)
                    {
                      const auto dof = cell->vertex_dof_index(vertex, c);
                      grid.nodes.push_back(cell->vertex(vertex)[c] + d(dof));
                      displacement.values.push_back(float(d(dof)));
                      velocity.values.push_back(float(v(dof)));
                    }
                }
              for (unsigned int k = 0; k < grid.cell_fields.size(); ++k)
                grid.cell_fields[k].values.push_back((*cell_fields[k].first)[cell->active_cell_index()]);
            }
        grid.node_fields = {std::move(displacement), std::move(velocity)};
        records_.emplace_back(time, write_hdf5(grid, directory_, stem + ".h5", time, "Hexahedron", comm));
      }
    else
      {
        MappingQ1Eulerian<3, mesh::Vector> mapping(dh, d);
        DataOut<3>                         data_out;
        data_out.attach_dof_handler(dh);
        const std::vector<DataComponentInterpretation::DataComponentInterpretation> vector3(
          3, DataComponentInterpretation::component_is_part_of_vector);
        data_out.add_data_vector(d, std::vector<std::string>(3, "displacement"), DataOut<3>::type_dof_data, vector3);
        data_out.add_data_vector(v, std::vector<std::string>(3, "velocity"), DataOut<3>::type_dof_data, vector3);
        for (const auto &[field, name] : cell_fields)
          data_out.add_data_vector(*field, name, DataOut<3>::type_cell_data);
        data_out.build_patches(mapping);
        DataOutBase::VtkFlags flags;
        flags.time = time;
        data_out.set_flags(flags);
        records_.emplace_back(time, data_out.write_vtu_with_pvtu_record(directory_ + "/", "solution", records_.size(),
                                                                        comm, 4));
      }
    if (particles_->active())
      write_particles(time, d, v);
    if (Utilities::MPI::this_mpi_process(comm) == 0)
      write_series_files();
  }

  void
  FieldOutput::write_series_files() const
  {
    const auto has = [](const std::vector<std::pair<double, std::string>> &records, const bool vtu) {
      return std::any_of(records.begin(), records.end(), [&](const auto &r) { return is_vtu_record(r.second) == vtu; });
    };
    // One PVD time series: part 0 the mesh (converted cells flagged), part 1 the particles.
    if (has(records_, true) || has(particle_records_, true))
      {
        std::ostringstream pvd;
        pvd.precision(16);
        pvd << "<?xml version=\"1.0\"?>\n<VTKFile type=\"Collection\" version=\"0.1\" "
               "byte_order=\"LittleEndian\">\n<Collection>\n";
        for (const auto &[t, file] : records_)
          if (is_vtu_record(file))
            pvd << "  <DataSet timestep=\"" << t << "\" group=\"\" part=\"0\" file=\"" << file << "\"/>\n";
        for (const auto &[t, file] : particle_records_)
          if (is_vtu_record(file))
            pvd << "  <DataSet timestep=\"" << t << "\" group=\"\" part=\"1\" file=\"" << file << "\"/>\n";
        pvd << "</Collection>\n</VTKFile>\n";
        base::write_file_atomically(pvd_path(), pvd.str());
      }
    if (has(particle_records_, true))
      {
        std::vector<std::pair<double, std::string>> vtu;
        std::copy_if(particle_records_.begin(), particle_records_.end(), std::back_inserter(vtu),
                     [](const auto &r) { return is_vtu_record(r.second); });
        std::ostringstream pvd;
        DataOutBase::write_pvd_record(pvd, vtu);
        base::write_file_atomically(directory_ + "/particles.pvd", pvd.str());
      }
    // The HDF5 series: the XDMF files are rewritten after the .h5 file is complete.
    if (has(records_, false))
      base::write_file_atomically(directory_ + "/solution.xdmf", xdmf_series(records_));
    if (has(particle_records_, false))
      base::write_file_atomically(directory_ + "/particles.xdmf", xdmf_series(particle_records_));
  }

  void
  FieldOutput::write_particles(const double time, const mesh::Vector &d, const mesh::Vector &v)
  {
    const auto         comm    = discretization_->communicator();
    const unsigned int rank    = Utilities::MPI::this_mpi_process(comm);
    const unsigned int n_ranks = Utilities::MPI::n_mpi_processes(comm);
    const auto        &set     = particles_->particles();
    const unsigned int n       = particles_->n_owned();
    const std::string  stem    = "particles_" + Utilities::int_to_string(particle_records_.size(), 4);
    const auto         piece   = [&](const unsigned int r) { return stem + "." + Utilities::int_to_string(r, 4) + ".vtu"; };

    // The fields, in file order: name, components (1 or 3), n x components values.
    struct Column
    {
      std::string         name;
      unsigned int        components;
      std::vector<double> values;
    };
    std::vector<Column> columns;
    const auto vector_field = [&](const char *name, const mesh::Vector &x) {
      Column c{name, 3, std::vector<double>(3 * std::size_t(n))};
      for (unsigned int i = 0; i < n; ++i)
        for (unsigned int k = 0; k < 3; ++k)
          c.values[3 * std::size_t(i) + k] = x.local_element(set.local_dof(i) + k);
      columns.push_back(std::move(c));
    };
    const auto scalar_field = [&](const char *name, const auto &value) {
      Column c{name, 1, std::vector<double>(n)};
      for (unsigned int i = 0; i < n; ++i)
        c.values[i] = value(i);
      columns.push_back(std::move(c));
    };
    vector_field("displacement", d);
    vector_field("velocity", v);
    const char *names[6] = {"stress_xx", "stress_yy", "stress_zz", "stress_yz", "stress_xz", "stress_xy"};
    for (unsigned int c = 0; c < 6; ++c)
      scalar_field(names[c], [&](const unsigned int i) { return particles_->stress(i)[c]; });
    scalar_field("von_mises_stress", [&](const unsigned int i) { return materials::von_mises_stress(particles_->stress(i)); });
    scalar_field("plastic_strain",
                 [&](const unsigned int i) { return particles_->state_value(i, materials::slot::plastic_strain); });
    scalar_field("failed", [&](const unsigned int i) { return particles_->state_value(i, materials::slot::failed); });
    scalar_field("scaled_damage", [&](const unsigned int i) { return particles_->state_value(i, "scaled damage"); });
    scalar_field("strength_factor", [&](const unsigned int i) {
      return particles_->material(i).state_slot("strength factor") < 0 ? 1. :
                                                                         particles_->state_value(i, "strength factor");
    });
    scalar_field("intact_bonds", [&](const unsigned int i) { return double(set.intact_bonds(i)); });
    scalar_field("material", [&](const unsigned int i) { return double(set.body(i)); });
    scalar_field("volume", [&](const unsigned int i) { return set.volume(i); });
    scalar_field("interface", [&](const unsigned int i) { return set.is_interface(i) ? 1. : 0.; });
    scalar_field("mpi_rank", [&](const unsigned int) { return double(rank); });
    const auto position = [&](const unsigned int i, const unsigned int c) {
      return set.position(i)[c] + d.local_element(set.local_dof(i) + c);
    };

    if (resolved_format_ == "hdf5")
      {
        Hdf5Grid grid;
        grid.cells.resize(n);
        for (unsigned int i = 0; i < n; ++i)
          {
            grid.cells[i] = i;
            for (unsigned int c = 0; c < 3; ++c)
              grid.nodes.push_back(position(i, c));
          }
        for (const auto &c : columns)
          grid.node_fields.push_back({c.name, c.components, std::vector<float>(c.values.begin(), c.values.end())});
        particle_records_.emplace_back(time, write_hdf5(grid, directory_, stem + ".h5", time, "Polyvertex", comm));
        return;
      }

    std::ostringstream out;
    out.precision(9);
    out << "<?xml version=\"1.0\"?>\n<VTKFile type=\"UnstructuredGrid\" version=\"0.1\" byte_order=\"LittleEndian\">\n"
        << "<UnstructuredGrid>\n<FieldData><DataArray type=\"Float64\" Name=\"TIME\" NumberOfTuples=\"1\" "
           "format=\"ascii\">"
        << time << "</DataArray></FieldData>\n<Piece NumberOfPoints=\"" << n << "\" NumberOfCells=\"" << n
        << "\">\n<Points><DataArray type=\"Float64\" NumberOfComponents=\"3\" format=\"ascii\">\n";
    for (unsigned int i = 0; i < n; ++i)
      for (unsigned int c = 0; c < 3; ++c)
        out << position(i, c) << (c == 2 ? "\n" : " ");
    out << "</DataArray></Points>\n<Cells><DataArray type=\"Int64\" Name=\"connectivity\" format=\"ascii\">\n";
    for (unsigned int i = 0; i < n; ++i)
      out << i << "\n";
    out << "</DataArray><DataArray type=\"Int64\" Name=\"offsets\" format=\"ascii\">\n";
    for (unsigned int i = 0; i < n; ++i)
      out << i + 1 << "\n";
    out << "</DataArray><DataArray type=\"UInt8\" Name=\"types\" format=\"ascii\">\n";
    for (unsigned int i = 0; i < n; ++i)
      out << "1\n";
    out << "</DataArray></Cells>\n<PointData>\n";
    for (const auto &c : columns)
      {
        out << "<DataArray type=\"Float64\" Name=\"" << c.name << "\""
            << (c.components == 3 ? " NumberOfComponents=\"3\"" : "") << " format=\"ascii\">\n";
        for (std::size_t j = 0; j < c.values.size(); ++j)
          out << c.values[j] << (c.components == 1 || j % 3 == 2 ? "\n" : " ");
        out << "</DataArray>\n";
      }
    out << "</PointData>\n</Piece>\n</UnstructuredGrid>\n</VTKFile>\n";
    base::write_file_atomically(directory_ + "/" + piece(rank), out.str());

    if (rank == 0)
      {
        std::ostringstream p;
        p << "<?xml version=\"1.0\"?>\n<VTKFile type=\"PUnstructuredGrid\" version=\"0.1\" "
             "byte_order=\"LittleEndian\">\n<PUnstructuredGrid GhostLevel=\"0\">\n"
             "<PPoints><PDataArray type=\"Float64\" NumberOfComponents=\"3\"/></PPoints>\n<PPointData>\n";
        for (const auto &c : columns)
          p << "<PDataArray type=\"Float64\" Name=\"" << c.name << "\""
            << (c.components == 3 ? " NumberOfComponents=\"3\"" : "") << "/>\n";
        p << "</PPointData>\n";
        for (unsigned int r = 0; r < n_ranks; ++r)
          p << "<Piece Source=\"" << piece(r) << "\"/>\n";
        p << "</PUnstructuredGrid>\n</VTKFile>\n";
        base::write_file_atomically(directory_ + "/" + stem + ".pvtu", p.str());
      }
    particle_records_.emplace_back(time, stem + ".pvtu");
  }
} // namespace shard::output
