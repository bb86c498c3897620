// SPDX-License-Identifier: LGPL-2.1-or-later
#include <shard/materials/material.h>
#include <shard/output/field_output.h>

#include <deal.II/base/mpi.h>
#include <deal.II/fe/mapping_q1_eulerian.h>
#include <deal.II/numerics/data_out.h>

#include <cstdio>
#include <filesystem>
#include <fstream>
#include <sstream>

namespace shard::output
{
  using namespace dealii;

  void
  write_file_atomically(const std::string &path, const std::string &content)
  {
    const std::string tmp = path + ".tmp";
    {
      std::ofstream out(tmp);
      out << content;
      if (!out)
        throw std::runtime_error("cannot write '" + tmp + "'");
    }
    std::filesystem::rename(tmp, path);
  }

  bool
  FieldOutput::declare_parameters(ParameterHandler &prm)
  {
    if (declared_)
      return false;
    declared_ = true;
    prm.enter_subsection("J - Output");
    prm.add_parameter("directory", directory_,
                      "Output directory (created if missing); relative paths are relative to the "
                      "working directory.");
    prm.add_parameter("interval", interval_,
                      "Simulated time between field outputs (PVTU); 0 writes the first and last step only. "
                      "Unit: s. Range: >= 0.",
                      Patterns::Double(0));
    prm.add_parameter("history interval", history_interval_,
                      "Steps between rows of history.csv. Unit: 1. Range: >= 1.", Patterns::Integer(1));
    prm.add_parameter("progress interval", progress_interval_,
                      "Wall-clock time between progress lines on stderr; 0 disables them. Unit: s. Range: >= 0.",
                      Patterns::Double(0));
    prm.leave_subsection();
    return true;
  }

  void
  FieldOutput::check_parameters(const base::PrmSource &source) const
  {
    if (directory_.empty())
      source.fail("J - Output/directory", "", "must not be empty.");
  }

  void
  FieldOutput::prepare(const mesh::Discretization &discretization, const fe::HexForce &hex)
  {
    discretization_ = &discretization;
    hex_            = &hex;
    records_.clear();
    if (Utilities::MPI::this_mpi_process(discretization.communicator()) == 0)
      {
        std::error_code ec;
        std::filesystem::create_directories(directory_, ec);
        if (ec || !std::filesystem::is_directory(directory_))
          throw base::InputError("J - Output/directory = " + directory_ + ": cannot create the directory (" +
                                 ec.message() + ").");
      }
    MPI_Barrier(discretization.communicator());
  }

  void
  FieldOutput::write(const double time, const mesh::Vector &d, const mesh::Vector &v)
  {
    const auto        &dh   = discretization_->dof_handler();
    const auto         comm = discretization_->communicator();
    const unsigned int n    = discretization_->triangulation().n_active_cells();
    Vector<float> sxx(n), syy(n), szz(n), syz(n), sxz(n), sxy(n), vm(n), eps(n), failed(n), body(n), rank(n);
    const float this_rank = Utilities::MPI::this_mpi_process(comm);
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
      {&failed, "failed"}, {&body, "material"}, {&rank, "mpi_rank"}};
    for (const auto &[field, name] : cell_fields)
      data_out.add_data_vector(*field, name, DataOut<3>::type_cell_data);
    data_out.build_patches(mapping);
    DataOutBase::VtkFlags flags;
    flags.time = time;
    data_out.set_flags(flags);
    const std::string pvtu =
      data_out.write_vtu_with_pvtu_record(directory_ + "/", "solution", records_.size(), comm, 4);
    records_.emplace_back(time, pvtu);
    if (Utilities::MPI::this_mpi_process(comm) == 0)
      {
        std::ostringstream pvd;
        DataOutBase::write_pvd_record(pvd, records_);
        write_file_atomically(pvd_path(), pvd.str());
      }
  }
} // namespace shard::output
