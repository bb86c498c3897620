// SPDX-License-Identifier: LGPL-2.1-or-later
/**
 * @file field_output.h
 * @brief ParaView output of the fields (subsection `K - Output`), written on the deformed mesh:
 *        one PVTU per output time collected in a PVD time series, or (`format = hdf5`, the
 *        default above 16 ranks) one HDF5 file per output time indexed by an XDMF file.
 * @ingroup output
 */
#pragma once

#include <shard/base/parameters.h>
#include <shard/fe/hex_force.h>
#include <shard/particles/spg_force.h>
#include <shard/mesh/discretization.h>

#include <array>
#include <string>
#include <utility>
#include <vector>

namespace shard::output
{
  /**
   * @brief Writes displacement and velocity (nodal), stress, von Mises stress, effective plastic
   * strain, failure flag, material (body) and MPI rank (per element) to `<dir>/solution_NNNN.pvtu`
   * and keeps `<dir>/solution.pvd` current (written to a temporary file, then renamed).
   *
   * With `format = hdf5` the same fields go to `<dir>/solution_NNNN.h5` (one file per output
   * time, written by all ranks through parallel HDF5: nodes once per rank, cell fields per cell)
   * and `<dir>/solution.xdmf` indexes them; the particles go to `particles_NNNN.h5` and
   * `particles.xdmf`. `auto` chooses hdf5 from 17 ranks on (resolve_format()): there one .vtu
   * per rank per output is thousands of files. Layout and cost: doc/manual/output.md.
   */
  class FieldOutput : public base::ParameterOwner
  {
  public:
    bool
    declare_parameters(dealii::ParameterHandler &prm) override;

    void
    check_parameters(const base::PrmSource &source) const override;

    /// Output directory (created by prepare()).
    const std::string &
    directory() const
    {
      return directory_;
    }

    /// Simulated time between field outputs (s); 0: first and last step only.
    double
    interval() const
    {
      return interval_;
    }

    /// Steps between rows of history.csv.
    unsigned int
    history_interval() const
    {
      return history_interval_;
    }

    /// Whether the run ends with fragments.png.
    bool
    fragment_plots() const
    {
      return fragment_plots_;
    }

    /// Debris fragments of fewer nodes than this are dust (`dust particles`, >= 1).
    unsigned int
    dust_particles() const
    {
      return dust_particles_;
    }

    /// Unit vector of `debris axis` (checked by check_parameters()).
    std::array<double, 3>
    debris_axis() const;

    /// `auto` -> "hdf5" from 17 ranks on, "vtu" below; "vtu" and "hdf5" stay as they are.
    static std::string
    resolve_format(const std::string &format, unsigned int n_ranks);

    /// Wall-clock seconds between progress lines.
    double
    progress_interval() const
    {
      return progress_interval_;
    }

    /// Binds the model and checks that the output directory can be created. @note Collective.
    void
    prepare(const mesh::Discretization &discretization, const fe::HexForce &hex,
            const particles::SpgForce &particles);

    /// Creates the output directory: when the run starts, after step 0 passed. @note Collective.
    void
    create_directory() const;

    /**
     * @brief Writes the fields at @p time: the mesh series solution.pvd and, with particles,
     * the point series particles.pvd (positions X + u, physical displacement u, coefficient
     * velocity, stress, von Mises stress, plastic strain, failed, material, rank); with
     * `format = hdf5` the series solution.xdmf and particles.xdmf instead.
     * Writes nothing with `K - Output/fields = false`.
     * @p d (physical displacement) and @p v must have ghost values set.
     * @note Collective.
     */
    void
    write(double time, const mesh::Vector &d, const mesh::Vector &v);

    /// Path of the PVD file.
    std::string
    pvd_path() const
    {
      return directory_ + "/solution.pvd";
    }

    /// Path of the file a user opens in ParaView: solution.pvd, or solution.xdmf with hdf5.
    std::string
    series_path() const
    {
      return directory_ + (resolved_format_ == "hdf5" ? "/solution.xdmf" : "/solution.pvd");
    }

    /**
     * The records (time, entry) of the mesh and particle series so far (checkpoint). An entry is
     * the .pvtu file name of a VTU output or the XDMF grid (XML text) of an HDF5 output, so that
     * a restart in the other format continues both series files.
     */
    std::array<std::vector<std::pair<double, std::string>>, 2>
    records() const
    {
      return {{records_, particle_records_}};
    }

    /// Restores the records of a checkpoint: the next write continues the series.
    void
    restore_records(const std::array<std::vector<std::pair<double, std::string>>, 2> &records)
    {
      records_          = records[0];
      particle_records_ = records[1];
    }

  private:
    std::string  directory_         = "output";
    double       interval_          = 0.;
    unsigned int history_interval_  = 1;
    double       progress_interval_ = 2.;
    bool         fragment_plots_    = true;
    bool         fields_            = true;
    unsigned int dust_particles_    = 8;
    std::string  debris_axis_       = "0, 0, -1";
    std::string  format_            = "auto";
    std::string  resolved_format_   = "vtu";

    const mesh::Discretization                *discretization_ = nullptr;
    const fe::HexForce                        *hex_            = nullptr;
    const particles::SpgForce                 *particles_      = nullptr;
    std::vector<std::pair<double, std::string>> records_, particle_records_;

    void
    write_particles(double time, const mesh::Vector &d, const mesh::Vector &v);

    /// Rewrites solution.pvd/solution.xdmf (and the particle series) from the records. Rank 0.
    void
    write_series_files() const;
  };
} // namespace shard::output
