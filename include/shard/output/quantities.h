// SPDX-License-Identifier: LGPL-2.1-or-later
/**
 * @file quantities.h
 * @brief Scene quantities of interest (subsection `L - Quantities`): reaction forces, applied loads,
 *        extents, point stresses and velocities, maxima of history variables, odd-even
 *        indicator, L2 error against an exact displacement.
 * @ingroup output
 */
#pragma once

#include <shard/base/parameters.h>
#include <shard/bc/boundary_conditions.h>
#include <shard/fe/hex_force.h>
#include <shard/particles/spg_force.h>
#include <shard/mesh/discretization.h>

#include <deal.II/base/function_parser.h>

#include <memory>
#include <string>
#include <vector>

namespace shard::output
{
  /**
   * @brief The quantities a scene asks for, one column each in history.csv.
   *
   * Syntax of `quantities`: entries `name = kind arguments` separated by ';'. Kinds:
   * - `reaction <condition> <x|y|z|n>`: sum of the reaction forces of a kinematic condition (N);
   *   n is the component along a rigid wall's normal.
   * - `load <condition> <x|y|z>`: sum of the forces a traction or blast condition applies at the
   *   time of the row (N).
   * - `max_coordinate <body> <x|y|z>`, `min_coordinate <body> <x|y|z>`: extent of the deformed body (m).
   * - `max_radius <body> <x|y|z> [boundary id]`: largest distance of a node from the axis through
   *   the origin (m), over the body or the nodes of one boundary id.
   * - `stress <x> <y> <z> <xx|yy|zz|yz|xz|xy|vm|p>`: stress of the element containing the
   *   reference point (Pa; p is the pressure, compression positive).
   * - `velocity <x> <y> <z> <x|y|z>`: velocity of the node nearest the reference point (m/s).
   * - `max_plastic_strain <body|all>`: largest effective plastic strain (1).
   * - `odd_even <particle body>`: |sum_I s_I u_I| / sum_I |u_I|, s_I = (-1)^(i+j+k) (1).
   * - `l2_error <body|all> <ux> <uy> <uz>`: mass-weighted RMS distance of the displacement from
   *   an exact one, sqrt(sum_I m_I |u_I - u(X_I, t)|^2 / sum_I m_I) over the nodes (particles) of
   *   the body (m); m_I the lumped mass, u_I the physical displacement for particle bodies, the
   *   three muparser expressions of x, y, z (reference coordinates) and t contain no spaces.
   * - `kinetic_energy <body|all> <x|y|z> <from> <to>`: sum of m_I |v_I|^2 / 2 over the nodes and
   *   particles whose reference coordinate along the axis lies in [from, to] (J).
   * - `stress_range <body|all> <xx|yy|zz|yz|xz|xy>`: largest minus smallest stress component over
   *   the elements and particles (Pa; the patch test).
   * - `mass <body|all>`: sum of rho0 V0 over the elements and rho0 V_I over the particles, from
   *   their volumes, not from the mass vector (kg; conversion must keep it exact).
   */
  class Quantities : public base::ParameterOwner
  {
  public:
    bool
    declare_parameters(dealii::ParameterHandler &prm) override;

    void
    check_parameters(const base::PrmSource &source) const override;

    /**
     * @brief Resolves bodies, conditions and points. Throws InputError located through @p source
     * for a body, condition or boundary id that does not exist and for an exact solution
     * (l2_error) that is not finite at one of its nodes at t = 0. @note Collective.
     */
    void
    prepare(const mesh::Discretization &discretization, const fe::HexForce &hex,
            const bc::BoundaryConditions &conditions, const particles::SpgForce &particles,
            const base::PrmSource &source = base::PrmSource());

    /// Column names.
    std::vector<std::string>
    names() const;

    /**
     * @brief Evaluates every quantity.
     * @param d displacement now (owned entries used)
     * @param v velocity at the same time (owned entries used)
     * @param mass lumped mass (owned entries used; for `l2_error`)
     * @param t time of @p d and @p v (s; for `l2_error`)
     * @note Collective.
     */
    std::vector<double>
    evaluate(const mesh::Vector &d, const mesh::Vector &v, const mesh::Vector &mass, double t) const;

  private:
    struct Item
    {
      std::string              name, kind;
      std::vector<std::string> args;
      int                      body = -1, component = 0, boundary_id = -1;
      std::vector<unsigned int> nodes;
      std::vector<double>       signs; // odd_even: (-1)^(i+j+k) per node
      std::shared_ptr<dealii::FunctionParser<3>> exact; // l2_error: u(x, y, z, t)
      int                      element = -1; // local element index owning the point
      int                      particle = -1; // or the owned particle closest to it
      unsigned int             node    = 0;
      bool                     owns_node = false;
    };
    std::string                   text_;
    std::vector<Item>             items_;
    const mesh::Discretization   *discretization_ = nullptr;
    const fe::HexForce           *hex_            = nullptr;
    const particles::SpgForce    *particles_      = nullptr;
    const bc::BoundaryConditions *conditions_     = nullptr;

    std::vector<Item>
    parse(std::string &error) const;

    /// prepare(): throws InputError located through @p source for item @p it, reason @p why.
    [[noreturn]] void
    fail(const base::PrmSource &source, const Item &it, const std::string &why) const;

    /// prepare(): the first argument of @p it names a body or 'all' (body -1).
    void
    resolve_body_or_all(Item &it, const base::PrmSource &source) const;

    /// prepare() of `reaction` and `load`: the condition (and its type) and the component.
    void
    resolve_condition(Item &it, const base::PrmSource &source) const;

    /// prepare() of `max_coordinate`, `min_coordinate` and `max_radius`: body, axis, boundary id, nodes.
    void
    resolve_extent(Item &it, const base::PrmSource &source) const;

    /// prepare() of `odd_even`: the owned particles of the body and their signs (-1)^(i+j+k).
    /// @note Collective.
    void
    resolve_odd_even(Item &it, const base::PrmSource &source) const;

    /// prepare() of `kinetic_energy`: body, axis and the owned nodes in [from, to].
    void
    resolve_kinetic_energy(Item &it, const base::PrmSource &source) const;

    /// prepare() of `l2_error` and `mean_velocity`: body, axis, the owned nodes; for l2_error
    /// checks that the exact solution is finite at them. @note Collective.
    void
    resolve_body_nodes(Item &it, const base::PrmSource &source) const;

    /// prepare() of `stress` and `velocity`: the component and the rank, element, particle or
    /// node nearest the reference point. @note Collective.
    void
    resolve_point(Item &it, const base::PrmSource &source) const;

    /// Sets the local element or owned particle nearest @p p in @p it; returns its distance.
    double
    nearest_stress_point(Item &it, const double (&p)[3]) const;

    /// Sets the owned node nearest @p p in @p it; returns its distance.
    double
    nearest_node(Item &it, const double (&p)[3]) const;
  };
} // namespace shard::output
