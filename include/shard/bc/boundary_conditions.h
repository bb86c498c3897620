// SPDX-License-Identifier: LGPL-2.1-or-later
/**
 * @file boundary_conditions.h
 * @brief Kinematic (fixed, prescribed velocity, frictionless rigid wall) and force-type
 *        (traction, blast) boundary conditions. Subsection `I - Boundary conditions`.
 * @ingroup bc
 */
#pragma once

#include <shard/base/parameters.h>
#include <shard/bc/blast_load.h>
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
    /// fixed, velocity, traction, rigid wall or blast.
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
    /// Blast: mass of the charge (kg); the TNT-equivalent mass is charge_mass * tnt_equivalence.
    double charge_mass = 1.;
    /// Blast: TNT equivalence factor of the explosive (1 for TNT).
    double tnt_equivalence = 1.;
    /// Blast: charge centre "x, y, z" (m).
    std::string charge_position = "0, 0, 0";
    /// Blast: hemispherical (surface burst) or spherical (free-air burst).
    std::string burst = "hemispherical";
  };

  /**
   * @brief All boundary conditions of a scene.
   *
   * Kinematic conditions act on the velocity of the next half step after the unconstrained
   * update; the velocity change defines the reaction force r = m (v - v_free) / dt, whose work
   * enters the energy balance. A frictionless rigid wall stops the normal velocity of every
   * boundary node whose predicted position would cross the plane and releases the node when
   * its free motion leaves the plane (a unilateral constraint).
   *
   * A blast condition is a reference-face pressure (the load does not follow the deforming
   * surface): each loaded face gets, at its reference centre x_f with reference outward area
   * vector A_f, the Kingery-Bulmash / Friedlander overpressure p_f(t) of BlastCharge::at()
   * (scaled distance, arrival time and angle of incidence of x_f), and each of its four nodes
   * the force -p_f(t) A_f / 4. Like a traction, its work enters `external_work`
   * (doc/manual/blast.md).
   */
  class BoundaryConditions : public base::ParameterOwner
  {
  public:
    bool
    declare_parameters(dealii::ParameterHandler &prm) override;

    void
    check_parameters(const base::PrmSource &source) const override;

    /**
     * @brief Builds node and face lists, parses functions and evaluates the blast parameters of
     * every loaded face. Throws InputError naming the key in @p source for: a blast face outside
     * the Kingery-Bulmash range of scaled distance (`charge position`), a boundary id the body
     * does not have, two kinematic conditions (fixed, velocity) on one component of the same faces,
     * and a velocity or traction function that is not finite at one of its nodes at t = 0.
     * @note Collective.
     */
    void
    prepare(const mesh::Discretization &discretization, const base::PrmSource &source = base::PrmSource());

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

    /**
     * @brief Diagnostic of a run whose energy became non-finite: the first velocity or traction
     * condition whose function is not finite at one of this rank's nodes at time @p t, with the
     * point ("" if none). Not collective.
     */
    std::string
    non_finite_report(double t) const;

    /// Adds traction and blast forces at time @p t into the owned entries of @p f.
    void
    add_external_forces(double t, mesh::Vector &f) const;

    /**
     * @brief Sum of the forces of traction or blast condition @p name over this rank's owned
     * nodes at time @p t (N); zero for other types.
     */
    std::array<double, 3>
    applied_force(const std::string &name, double t) const;

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
      /// Blast: one entry per loaded face that has an owned node.
      struct BlastFace
      {
        BlastPoint            load;
        std::array<double, 3> area{}; // reference outward area vector (m^2)
        std::vector<unsigned int> nodes; // first local DOF of each owned node of the face
      };
      std::vector<BlastFace>    blast_faces;
    };

    void
    add_forces(const Active &a, double t, mesh::Vector &f) const;

    /// Reference positions of the owned nodes a velocity or traction condition @p a acts on.
    std::vector<dealii::Point<3>>
    reference_points(const Active &a) const;

    /// Calls visit(node, component, force) for each nodal force of traction or blast condition
    /// @p a at time @p t (node: first local DOF of an owned node; N). One loop serves the
    /// assembly and the applied-force sum.
    template <typename Visit>
    void
    for_each_nodal_force(const Active &a, double t, Visit &&visit) const;

    void
    prepare_blast(const mesh::Discretization &discretization, unsigned int body, const base::PrmSource &source,
                  Active &a);

    std::string                                                  names_text_;
    std::vector<std::string>                                     names_;
    bool                                                         names_declared_ = false;
    std::map<std::string, std::unique_ptr<ConditionParameters>> params_;
    std::vector<Active>                                          active_;
    std::map<std::string, std::array<double, 3>>                reaction_;
    const mesh::Discretization                                  *discretization_ = nullptr;
  };
} // namespace shard::bc
