// SPDX-License-Identifier: LGPL-2.1-or-later
/**
 * @file material.h
 * @brief The batch material interface shared by FE quadrature points and particles.
 * @ingroup materials
 *
 * A material model is called once per batch of points (a chunk of hexahedra or particles),
 * never per point. Its per-point history lives in a flat array owned by the caller and
 * described by named slots, so output, restart and history transfer need no model code.
 *
 * Conventions (see doc/manual/materials.md):
 * - Symmetric tensors are stored as 6 numbers in the order xx, yy, zz, yz, xz, xy
 *   (tensor components, not engineering shear strains).
 * - Stress is Cauchy, tension positive, in Pa. The caller rotates the stress of the previous
 *   step into the current frame (objective rate) before the call; the model adds the
 *   constitutive increment.
 * - The strain increment is the rate of deformation times dt, evaluated at mid-step.
 */
#pragma once

#include <shard/base/parameters.h>

#include <cmath>
#include <iosfwd>
#include <array>
#include <memory>
#include <string>
#include <vector>

namespace shard::materials
{
  /// Number of stored components of a symmetric tensor.
  inline constexpr unsigned int n_sym = 6;

  /**
   * @brief Input and output of one material call for @p n points.
   *
   * All pointers address arrays with @p n rows; row i of a 6-column array starts at 6 i,
   * row i of the state starts at i * n_state_slots().
   */
  struct PointBatch
  {
    /// Number of points.
    unsigned int n = 0;
    /// Time step of this update (s).
    double dt = 0.;
    /// In: strain increment D dt at mid-step, 6 per point (1).
    const double *strain_increment = nullptr;
    /// In: relative volume J = V / V0 at the end of the step, 1 per point (1).
    const double *relative_volume = nullptr;
    /// In: characteristic length of the point's volume (element or particle size), 1 per point (m).
    const double *characteristic_length = nullptr;
    /// In: stress at the start of the step rotated to the current frame; out: stress at the end (Pa).
    double *stress = nullptr;
    /// In/out: history variables, n_state_slots() per point.
    double *state = nullptr;
    /// Out: dilatational wave speed sqrt((K + 4G/3)/rho0) of the current state, 1 per point (m/s).
    double *wave_speed = nullptr;
  };

  /**
   * @brief A constitutive model with its own parameters.
   *
   * Each instance belongs to one named subsection `C - Materials/<name>`; its parameters
   * are declared with deal.II's ParameterHandler::add_parameter, bound to members.
   */
  class Material
  {
  public:
    virtual ~Material() = default;

    /// Registry name of the model ("elastic", "von mises", ...).
    virtual std::string
    model_name() const = 0;

    /**
     * @brief Declares the model's keys in the current subsection of @p prm, bound to members.
     */
    virtual void
    declare_parameters(dealii::ParameterHandler &prm) = 0;

    /**
     * @brief Checks the parsed values; @p path is `C - Materials/<name>`.
     * Throws base::InputError naming key, file line and allowed range.
     */
    virtual void
    check_parameters(const base::PrmSource &source, const std::string &path) const = 0;

    /// Builds derived data (moduli, tables) after the parameters are parsed and checked.
    virtual void
    prepare() = 0;

    /// Reference density rho0 (kg/m^3).
    virtual double
    density() const = 0;

    /// Dilatational wave speed of the undeformed material (m/s), for the first time step.
    virtual double
    initial_wave_speed() const = 0;

    /**
     * @brief Bulk and shear modulus {K, G} of the undamaged material at zero pressure (Pa), for
     * the elastic energy estimate sigma : C^-1 : sigma / 2 (conversion energy bookkeeping).
     */
    virtual std::array<double, 2>
    elastic_moduli() const = 0;

    /**
     * @brief Stored elastic energy density estimate (J per reference m^3) of a point with Cauchy
     * stress @p stress (xx, yy, zz, yz, xz, xy) and relative volume @p jacobian: K (ln J)^2 / 2
     * from the volume (the pressure of the elastic and von Mises models is K ln J) plus
     * s : s / (4 G) from the deviatoric stress, with K, G of elastic_moduli(). The conversion
     * of elements to particles books the change of this estimate (doc/manual/hybrid.md).
     * Virtual so that a model with another stored-energy form can give its own.
     */
    virtual double
    elastic_energy_density(const double *stress, double jacobian) const;

    /// Names of the history slots, in storage order.
    virtual std::vector<std::string>
    state_slot_names() const = 0;

    /**
     * @brief Whether the model is rigid (model `rigid`): elements of it carry no stress and
     * limit no step; their nodes move as one rigid body (time::RigidBodies). Default false.
     */
    virtual bool
    rigid() const
    {
      return false;
    }

    /// Number of history slots per point.
    unsigned int
    n_state_slots() const
    {
      return static_cast<unsigned int>(state_slot_names().size());
    }

    /// Index of the slot called @p name, or -1 if the model has none.
    int
    state_slot(const std::string &name) const;

    /// Writes the initial history of @p n points into @p state.
    virtual void
    initialize_state(unsigned int n, double *state) const;

    /**
     * @brief Writes the history slots that are fields of the reference position (K&C's
     * strength factor) for @p n points; the callers apply it after initialize_state() and
     * after every history transfer (conversion, restart), so that such a slot never mixes.
     * The default writes nothing.
     * @param positions reference positions, 3 per point (m)
     * @param state the points' history, n_state_slots() per point
     */
    virtual void
    set_position_fields(unsigned int n, const double *positions, double *state) const;

    /**
     * @brief Updates stress and history of a batch of points (one virtual call per batch).
     */
    virtual void
    update(const PointBatch &batch) const = 0;

    /**
     * @brief Writes the model's resolved parameter set as `set key = value` lines, for
     * models that generate parameters (the run echoes it into its output directory).
     * The default writes nothing.
     * @param out The stream, positioned inside the material's subsection.
     */
    virtual void
    write_resolved_parameters(std::ostream &out) const;
  };

  /// Standard slot names that output and failure checks look for.
  namespace slot
  {
    /// Effective plastic strain (1).
    inline constexpr const char *plastic_strain = "effective plastic strain";
    /// Failure flag: 0 intact, 1 failed (1).
    inline constexpr const char *failed = "failed";
  } // namespace slot

  /**
   * @brief Creates a model by registry name; returns nullptr for an unknown name.
   * All registrations sit in source/materials/library.cc.
   */
  std::unique_ptr<Material>
  create_material(const std::string &model_name);

  /// The registry names, joined by '|', for a Patterns::Selection.
  std::string
  material_model_names();

  /// Von Mises equivalent stress of a 6-component Cauchy stress (Pa).
  inline double
  von_mises_stress(const double *s)
  {
    const double p = (s[0] + s[1] + s[2]) / 3.;
    const double a = s[0] - p, b = s[1] - p, c = s[2] - p;
    return std::sqrt(1.5 * (a * a + b * b + c * c +
                            2. * (s[3] * s[3] + s[4] * s[4] + s[5] * s[5])));
  }
} // namespace shard::materials
