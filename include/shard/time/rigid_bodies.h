// SPDX-License-Identifier: LGPL-2.1-or-later
/**
 * @file rigid_bodies.h
 * @brief Rigid FE bodies (material model `rigid`): their nodes move as one rigid body.
 * @ingroup time
 */
#pragma once

#include <shard/materials/material_library.h>
#include <shard/mesh/discretization.h>

#include <deal.II/base/tensor.h>

#include <memory>
#include <vector>

namespace shard::time
{
  /**
   * @brief The rigid-body constraint of the kick (doc/manual/fe.md, "Rigid bodies").
   *
   * A body whose material is `rigid` has no internal force and no element step. After the
   * unconstrained kick v_i += dt a_i, project() replaces the velocities of its nodes by the
   * rigid motion with the same linear and angular momentum about the centre of mass:
   * V = P / M, omega = I^-1 L, v_i = V + omega x (x_i - x_c), with x_i = X_i + d_i. Since the
   * velocities before the kick were rigid, this is the Newton-Euler update of the body under
   * the sum of its nodal forces and their moment (the gyroscopic term omega x I omega is
   * dropped: first order in dt omega). The projection is m-orthogonal, so the constraint forces
   * do no work on the rigid motion. Positions follow by the drift of the nodes, which keeps the
   * body rigid to O((omega dt)^2) per step.
   */
  class RigidBodies
  {
  public:
    /**
     * @brief Finds the bodies with a rigid material.
     * @param mass the lumped mass vector of the run (kept by reference: it may change layout)
     */
    void
    prepare(const mesh::Discretization &discretization, const materials::MaterialLibrary &materials,
            const mesh::Vector &mass);

    /**
     * @brief Replaces the velocities of every rigid body's owned nodes by its rigid motion.
     * @param d displacement at the integer step (owned entries)
     * @param mass lumped mass (owned entries)
     * @param v velocity, unconstrained v^{n+1/2} in, rigid on the bodies' nodes out
     * @note Collective (one sum over ranks of 16 numbers per rigid body).
     */
    void
    project(const mesh::Vector &d, const mesh::Vector &mass, mesh::Vector &v) const;

    /**
     * @brief Before the drift d += dt v: adds to the rigid bodies' nodes the difference between
     * the exact rotation by omega dt about the centre and the straight step dt omega × r, and
     * keeps the velocities V + omega × r at the turned positions for rotate_velocities().
     * @param v the rigid velocities v^{n+1/2} (after project())
     * @param d displacement d^n (owned entries)
     * @note Collective.
     */
    void
    correct_drift(double dt, const mesh::Vector &v, mesh::Vector &d);

    /**
     * @brief After the drift: the rigid bodies' velocities turned with the body, so that the
     * next projection recovers omega exactly (without it a free spin would decay by
     * (omega dt)^2 per step).
     */
    void
    rotate_velocities(mesh::Vector &v) const;

  private:
    /// Mass, centre, velocity and angular velocity of one rigid body.
    struct Motion
    {
      double               mass = 0;
      dealii::Tensor<1, 3> centre, velocity, omega;
    };
    /// The motions of all rigid bodies from the nodal velocities @p v at positions X + @p d.
    std::vector<Motion>
    motions(const mesh::Vector &d, const mesh::Vector &mass, const mesh::Vector &v) const;
    /// Rebuilds the node lists if the layout changed.
    void
    refresh() const;

    const mesh::Discretization *discretization_ = nullptr;
    const mesh::Vector         *mass_           = nullptr;
    /// Velocities at the turned positions, from correct_drift() to rotate_velocities().
    std::vector<double>         turned_;
    std::vector<unsigned int>   bodies_;
    /// Owned nodes (first local DOF) of each rigid body, for the layout of partitioner_.
    mutable std::vector<std::vector<unsigned int>>                     nodes_;
    mutable std::shared_ptr<const dealii::Utilities::MPI::Partitioner> partitioner_;
  };
} // namespace shard::time
