// SPDX-License-Identifier: LGPL-2.1-or-later
/**
 * @file material_test.h
 * @brief `shard material-test`: one material point of any registered model driven along a
 *        strain/stress path (unconfined, triaxial, hydrostatic, ...), written as CSV, JSON and
 *        a PNG plot.
 * @ingroup driver
 *
 * Keys, control and outputs: doc/manual/materials.md, section "Material point driver".
 */
#pragma once

#include <shard/base/parameters.h>
#include <shard/materials/material.h>
#include <shard/materials/material_library.h>

#include <array>
#include <functional>
#include <iosfwd>
#include <string>
#include <vector>

namespace shard::driver
{
  /// The loading paths of the material point driver (x is the axial direction).
  enum class LoadPath
  {
    /// eps_xx prescribed (compression), sigma_yy = sigma_zz = 0.
    unconfined_compression,
    /// eps_xx prescribed (tension), sigma_yy = sigma_zz = 0.
    uniaxial_tension,
    /// Hydrostatic loading to p = confinement, then eps_xx prescribed with sigma_yy = sigma_zz = -confinement.
    triaxial_compression,
    /// eps_xx = eps_yy = eps_zz, the volumetric strain ln J prescribed.
    hydrostatic,
    /// As unconfined compression, targets of either sign (load reversals).
    cyclic,
    /// eps_xx = eps_yy prescribed, sigma_zz = 0.
    equal_biaxial_compression
  };

  /// The path names of the parameter file joined by '|', for a Patterns::Selection.
  std::string
  load_path_names();

  /**
   * @brief The path called @p name in the parameter file ("unconfined compression", ...).
   * @throws std::invalid_argument for an unknown name.
   */
  LoadPath
  parse_load_path(const std::string &name);

  /// The parameter-file name of @p path.
  std::string
  load_path_name(LoadPath path);

  /**
   * @brief How the point is driven: the path, the controlled strain targets and the step.
   *
   * The controlled strain c is eps_xx (all paths but hydrostatic; eps_xx = eps_yy for equal
   * biaxial compression) or the volumetric strain ln J (hydrostatic). It starts at 0 and visits
   * @ref targets in order, each leg in equal steps of at most @ref strain_increment; the time
   * step is |dc| / @ref strain_rate. All strains are logarithmic.
   */
  struct PathControl
  {
    /// The loading path.
    LoadPath path = LoadPath::unconfined_compression;
    /// Controlled strain values visited in order from 0 (1). Triaxial: eps_xx measured from
    /// the start of the axial phase.
    std::vector<double> targets = {-0.01};
    /// Largest change of the controlled strain per step (1), > 0.
    double strain_increment = 1e-5;
    /// Magnitude of the controlled strain rate (1/s), > 0.
    double strain_rate = 1e-5;
    /// Lateral compressive stress of the triaxial path (Pa), >= 0.
    double confinement = 0.;
    /// Passed to the model as PointBatch::characteristic_length (m), > 0.
    double characteristic_length = 0.1;
  };

  /**
   * @brief The state of the point after a step (one row of history.csv).
   */
  struct PointRecord
  {
    /// Time (s).
    double time = 0.;
    /// Step number, 0 for the initial state.
    unsigned int step = 0;
    /// Logarithmic normal strains xx, yy, zz (1); shear strains are zero.
    std::array<double, 3> strain = {{0., 0., 0.}};
    /// Cauchy stress xx, yy, zz, yz, xz, xy (Pa), tension positive.
    std::array<double, materials::n_sym> stress = {{0., 0., 0., 0., 0., 0.}};
    /// Wave speed returned by the model (m/s).
    double wave_speed = 0.;
    /// History slots of the model, in the model's order.
    std::vector<double> state;

    /// Volumetric strain ln J = eps_xx + eps_yy + eps_zz (1).
    double
    volumetric_strain() const
    {
      return strain[0] + strain[1] + strain[2];
    }

    /// Pressure p = -tr(sigma)/3, compression positive (Pa).
    double
    pressure() const
    {
      return -(stress[0] + stress[1] + stress[2]) / 3.;
    }

    /// Von Mises stress q (Pa).
    double
    q() const
    {
      return materials::von_mises_stress(stress.data());
    }
  };

  /// Outcome of a drive.
  struct DriveResult
  {
    /// 0 completed or ended at a limit point; 3 the model returned a non-finite value.
    int exit_code = 0;
    /**
     * True if the path ended early because a stress condition had no solution near the last
     * state: a limit point (snap-back) of a softening response under mixed control. The data up
     * to there are valid; the drive counts as completed (exit code 0) and says so.
     */
    bool limit_point = false;
    /// What stopped the drive (step, time, quantity); empty when completed.
    std::string message;
    /// Steps taken.
    unsigned int steps = 0;
    /// Steps of the hydrostatic phase of the triaxial path (0 for the other paths).
    unsigned int hydrostatic_steps = 0;
  };

  /**
   * @brief Drives one point of @p material (prepared) along @p control.
   *
   * Each step prescribes the controlled strain and solves for the one unknown normal strain
   * (eps_yy = eps_zz, or eps_zz for equal biaxial) so that the lateral stress equals its target,
   * by a bracketed secant (Illinois) iteration with bisection fallback on copies of stress and
   * state. Tolerance: |sigma - target| <= 1e-9 max(|sigma|, 1 MPa), |sigma| the largest normal
   * stress magnitude of the point (at least 1e-3 Pa). The model gets D dt = the increment of
   * the logarithmic strains, J = exp(eps_xx + eps_yy + eps_zz) at the end of the step and the
   * stress of the previous step.
   *
   * @param material A prepared model.
   * @param control The path, targets and step.
   * @param record Called with the initial state (step 0) and after every step.
   * @return exit_code 0, or 3 with a message naming step, time and quantity when the model
   *         returns a non-finite value or the lateral condition cannot be met.
   */
  DriveResult
  drive_material_point(const materials::Material                &material,
                       const PathControl                        &control,
                       const std::function<void(const PointRecord &)> &record);

  /**
   * @brief The program `shard material-test`: owns `C - Materials` (a MaterialLibrary) and
   * subsection `M - Material test`; drives the chosen material along the chosen path and writes
   * history.csv, summary.json, parameters.prm and material_test.png.
   */
  class MaterialTest : public base::ParameterOwner
  {
  public:
    /// Declares the keys of `M - Material test`.
    bool
    declare_parameters(dealii::ParameterHandler &prm) override;

    /**
     * @brief Checks the keys of `M - Material test`, including that `material` names a material
     * of `C - Materials` and that the targets parse and fit the path.
     * @throws base::InputError naming file, line, key, value and requirement.
     */
    void
    check_parameters(const base::PrmSource &source) const override;

    /**
     * @brief Declares, parses and checks `C - Materials` and `M - Material test` of @p source.
     * @throws base::InputError naming file, line, key and allowed range.
     */
    void
    read(const base::PrmSource &source);

    /// Writes every parameter with its documentation, in declaration order.
    void
    print_parameters(std::ostream &out) const;

    /**
     * @brief Prepares the material, creates the output directory, drives the point and writes
     * the outputs; with `plot = true` runs contrib/utilities/plot_material_test.py (a failure
     * there only prints a warning). Prints a one-line result (and warnings) to @p log.
     * @throws base::InputError if the output directory cannot be created.
     */
    DriveResult
    run(std::ostream &log);

    /// The control read from `M - Material test` (valid after read()).
    const PathControl &
    control() const
    {
      return control_;
    }

    /// Output directory.
    const std::string &
    output_directory() const
    {
      return output_directory_;
    }

  private:
    base::PrmSource            source_;
    dealii::ParameterHandler   prm_;
    materials::MaterialLibrary materials_;

    std::string material_              = "steel";
    std::string path_                  = "unconfined compression";
    std::string strain_targets_        = "-0.01";
    double      strain_increment_      = 1e-5;
    double      strain_rate_           = 1e-5;
    double      confinement_           = 0.;
    double      characteristic_length_ = 0.1;
    std::string output_directory_      = "material-test-output";
    bool        plot_                  = true;

    PathControl control_;
  };
} // namespace shard::driver
