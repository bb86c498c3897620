// SPDX-License-Identifier: LGPL-2.1-or-later
#include <shard/base/sections.h>
#include <shard/materials/material.h>
#include <shard/output/field_output.h>

#include <deal.II/base/mpi.h>
#include <deal.II/fe/mapping_q1_eulerian.h>
#include <deal.II/numerics/data_out.h>

#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <sstream>

#include <unistd.h>

namespace shard::output
{
  using namespace dealii;


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
                      "Simulated time between field outputs (PVTU); 0 writes the first and last step only. "
                      "Unit: s. Range: >= 0.",
                      Patterns::Double(0));
    prm.add_parameter("fields", fields_,
                      "Whether the run writes field files (PVTU/PVD of the mesh and the particles) at all; "
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

    MappingQ1Eulerian<3, mesh::Vector> mapping(dh, d);
    DataOut<3>                         data_out;
    data_out.attach_dof_handler(dh);
    const std::vector<DataComponentInterpretation::DataComponentInterpretation> vector3(
      3, DataComponentInterpretation::component_is_part_of_vector);
    data_out.add_data_vector(d, std::vector<std::string>(3, "displacement"), DataOut<3>::type_dof_data, vector3);
    data_out.add_data_vector(v, std::vector<std::string>(3, "velocity"), DataOut<3>::type_dof_data, vector3);
    const std::pair<Vector<float> *, const char *> cell_fields[] = {
      {&sxx, "stress_xx"}, {&syy, "stress_yy"}, {&szz, "stress_zz"}, {&syz, "stress_yz"},
      {&sxz, "stress_xz"}, {&sxy, "stress_xy"}, {&vm, "von_mises_stress"}, {&eps, "plastic_strain"},
      {&failed, "failed"}, {&body, "material"}, {&rank, "mpi_rank"}, {&converted, "converted"}};
    for (const auto &[field, name] : cell_fields)
      data_out.add_data_vector(*field, name, DataOut<3>::type_cell_data);
    data_out.build_patches(mapping);
    DataOutBase::VtkFlags flags;
    flags.time = time;
    data_out.set_flags(flags);
    const std::string pvtu =
      data_out.write_vtu_with_pvtu_record(directory_ + "/", "solution", records_.size(), comm, 4);
    records_.emplace_back(time, pvtu);
    if (particles_->active())
      write_particles(time, d, v);
    // One time series: part 0 the mesh (converted cells flagged), part 1 the particles.
    if (Utilities::MPI::this_mpi_process(comm) == 0)
      {
        std::ostringstream pvd;
        pvd.precision(16);
        pvd << "<?xml version=\"1.0\"?>\n<VTKFile type=\"Collection\" version=\"0.1\" "
               "byte_order=\"LittleEndian\">\n<Collection>\n";
        for (const auto &[t, file] : records_)
          pvd << "  <DataSet timestep=\"" << t << "\" group=\"\" part=\"0\" file=\"" << file << "\"/>\n";
        for (const auto &[t, file] : particle_records_)
          pvd << "  <DataSet timestep=\"" << t << "\" group=\"\" part=\"1\" file=\"" << file << "\"/>\n";
        pvd << "</Collection>\n</VTKFile>\n";
        base::write_file_atomically(pvd_path(), pvd.str());
      }
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

    std::ostringstream out;
    out.precision(9);
    out << "<?xml version=\"1.0\"?>\n<VTKFile type=\"UnstructuredGrid\" version=\"0.1\" byte_order=\"LittleEndian\">\n"
        << "<UnstructuredGrid>\n<FieldData><DataArray type=\"Float64\" Name=\"TIME\" NumberOfTuples=\"1\" "
           "format=\"ascii\">"
        << time << "</DataArray></FieldData>\n<Piece NumberOfPoints=\"" << n << "\" NumberOfCells=\"" << n
        << "\">\n<Points><DataArray type=\"Float64\" NumberOfComponents=\"3\" format=\"ascii\">\n";
    for (unsigned int i = 0; i < n; ++i)
      for (unsigned int c = 0; c < 3; ++c)
        out << set.position(i)[c] + d.local_element(set.local_dof(i) + c) << (c == 2 ? "\n" : " ");
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
    const auto vector_field = [&](const char *name, const mesh::Vector &x) {
      out << "<DataArray type=\"Float64\" Name=\"" << name << "\" NumberOfComponents=\"3\" format=\"ascii\">\n";
      for (unsigned int i = 0; i < n; ++i)
        for (unsigned int c = 0; c < 3; ++c)
          out << x.local_element(set.local_dof(i) + c) << (c == 2 ? "\n" : " ");
      out << "</DataArray>\n";
    };
    const auto scalar_field = [&](const char *name, const auto &value) {
      out << "<DataArray type=\"Float64\" Name=\"" << name << "\" format=\"ascii\">\n";
      for (unsigned int i = 0; i < n; ++i)
        out << value(i) << "\n";
      out << "</DataArray>\n";
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
    out << "</PointData>\n</Piece>\n</UnstructuredGrid>\n</VTKFile>\n";
    base::write_file_atomically(directory_ + "/" + piece(rank), out.str());

    if (rank == 0)
      {
        std::ostringstream p;
        p << "<?xml version=\"1.0\"?>\n<VTKFile type=\"PUnstructuredGrid\" version=\"0.1\" "
             "byte_order=\"LittleEndian\">\n<PUnstructuredGrid GhostLevel=\"0\">\n"
             "<PPoints><PDataArray type=\"Float64\" NumberOfComponents=\"3\"/></PPoints>\n<PPointData>\n"
             "<PDataArray type=\"Float64\" Name=\"displacement\" NumberOfComponents=\"3\"/>\n"
             "<PDataArray type=\"Float64\" Name=\"velocity\" NumberOfComponents=\"3\"/>\n";
        for (const char *name : {"stress_xx", "stress_yy", "stress_zz", "stress_yz", "stress_xz", "stress_xy",
                                 "von_mises_stress", "plastic_strain", "failed", "scaled_damage", "strength_factor",
                                 "intact_bonds", "material", "volume", "interface", "mpi_rank"})
          p << "<PDataArray type=\"Float64\" Name=\"" << name << "\"/>\n";
        p << "</PPointData>\n";
        for (unsigned int r = 0; r < n_ranks; ++r)
          p << "<Piece Source=\"" << piece(r) << "\"/>\n";
        p << "</PUnstructuredGrid>\n</VTKFile>\n";
        base::write_file_atomically(directory_ + "/" + stem + ".pvtu", p.str());
      }
    particle_records_.emplace_back(time, stem + ".pvtu");
    if (rank == 0)
      {
        std::ostringstream pvd;
        DataOutBase::write_pvd_record(pvd, particle_records_);
        base::write_file_atomically(directory_ + "/particles.pvd", pvd.str());
      }
  }
} // namespace shard::output
