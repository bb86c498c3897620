// SPDX-License-Identifier: LGPL-2.1-or-later
/**
 * @file boundary_conditions.h
 * @brief Kinematic (fixed, prescribed velocity, frictionless rigid wall) and force-type
 *        (traction) boundary conditions. Subsection `I - Boundary conditions`.
 * @ingroup bc
 */
#pragma once

#include <shard/base/parameters.h>
#include <shard/mesh/discretization.h>

#include <deal.II/base/function_parser.h>

#include <array>
#include <map>
#include <memory>
#include <string>
#include <vector>

namespace shard::bc
{
  /// Parameters of one boundary condition (subsection `I - Boundary conditions/<name>`).
  struct ConditionParameters
  {
    /// Name (the subsection name).
    std::string name;
    /// fixed, velocity, traction or rigid wall.
    std::string type = "fixed";
    /// Body the condition acts on.
    std::string body = "body";
    /// Boundary id of the body's faces; -1 for every boundary face of the body.
    int boundary_id = 0;
    /// Constrained components for fixed and velocity ("x, y, z" or a subset).
    std::string components = "x, y, z";
    /// Velocity (m/s) or traction (Pa): three muparser expressions of x, y, z, t separated by ';'.
    std::string function = "0; 0; 0";
    /// Rigid wall: a point on the plane (m).
    std::string wall_point = "0, 0, 0";
    /// Rigid wall: normal pointing towards the bodies (normalised internally).
    std::string wall_normal = "0, 0, 1";
  };

  /**
   * @brief All boundary conditions of a scene.
   *
   * Kinematic conditions act on the velocity of the next half step after the unconstrained
   * update; the velocity change defines the reaction force r = m (v - v_free) / dt, whose work
   * enters the energy balance. A frictionless rigid wall stops the normal velocity of every
   * boundary node whose predicted position would cross the plane and releases the node when
   * its free motion leaves the plane (a unilateral constraint).
   */
  class BoundaryConditions : public base::ParameterOwner
  {
  public:
    bool
    declare_parameters(dealii::ParameterHandler &prm) override;

    void
    check_parameters(const base::PrmSource &source) const override;

    /// Builds node lists and parses functions. @note Collective.
    void
    prepare(const mesh::Discretization &discretization);

    /// Names in input order.
    const std::vector<std::string> &
    names() const
    {
      return names_;
    }

    /// Type of condition @p name.
    const std::string &
    type(const std::string &name) const
    {
      return params_.at(name)->type;
    }

    /// Unit normal of rigid wall @p name.
    std::array<double, 3>
    wall_normal(const std::string &name) const;

    /**
     * @brief The faces every condition acts on: (body name, boundary id, -1 for all faces).
     * Particles on them interpolate (ParticleSet).
     */
    std::vector<std::pair<std::string, int>>
    faces() const;

    /// Adds traction forces at time @p t into the owned entries of @p f.
    void
    add_external_forces(double t, mesh::Vector &f) const;

    /**
     * @brief Applies the kinematic conditions to the velocity of the next half step.
     *
     * @param[in] t_half time at the middle of the next step (velocity functions are evaluated there)
     * @param[in] dt_avg weight of the kick (mean of the last and next step), for reactions
     * @param[in] dt_next next step size, for the rigid-wall prediction
     * @param[in] d displacement now
     * @param[in] mass lumped mass
     * @param[in] acceleration unconstrained acceleration of the kick
     * @param[in] dt_old last step size, for the work of the reactions
     * @param[in,out] v unconstrained velocity in, constrained velocity out
     * @return work of the reaction forces over the half steps before and after this kick (J, this rank)
     */
    std::pair<double, double>
    apply_kinematic(double t_half, double dt_avg, double dt_next, double dt_old, const mesh::Vector &d,
                    const mesh::Vector &mass, const mesh::Vector &acceleration, mesh::Vector &v);

    /**
     * @brief Makes the initial velocity @p v consistent with the kinematic conditions at t = 0:
     * fixed and prescribed components take their values, and nodes on a rigid wall lose their
     * normal velocity towards it (a perfectly plastic impact of the node).
     * @return the change of kinetic energy this caused on this rank (J), booked as boundary work
     */
    double
    apply_initial(const mesh::Vector &d, const mesh::Vector &mass, mesh::Vector &v);

    /// Sum of the reaction forces of condition @p name over this rank's nodes at the last kick (N).
    const std::array<double, 3> &
    reaction(const std::string &name) const
    {
      return reaction_.at(name);
    }

  private:
    struct Active
    {
      const ConditionParameters                          *p = nullptr;
      std::vector<unsigned int>                           nodes;
      std::vector<std::pair<unsigned int, double>>        areas;
      std::array<bool, 3>                                 mask{{true, true, true}};
      std::unique_ptr<dealii::FunctionParser<3>>          function;
      bool                                                time_only = false;
      std::array<double, 3>                               point{}, normal{};
    };

    std::string                                                  names_text_;
    std::vector<std::string>                                     names_;
    bool                                                         names_declared_ = false;
    std::map<std::string, std::unique_ptr<ConditionParameters>> params_;
    std::vector<Active>                                          active_;
    std::map<std::string, std::array<double, 3>>                reaction_;
    const mesh::Discretization                                  *discretization_ = nullptr;
  };
} // namespace shard::bc
