// SPDX-License-Identifier: LGPL-2.1-or-later
/**
 * @file element_converter.h
 * @brief Phase 4b of the step: elements that met a conversion criterion become particles
 *        (history transfer, particle set, stencils, ghost set and vector layout rebuilt).
 * @ingroup coupling
 */
#pragma once

#include <shard/base/parameters.h>
#include <shard/bc/boundary_conditions.h>
#include <shard/coupling/conversion.h>
#include <shard/fe/hex_force.h>
#include <shard/materials/material_library.h>
#include <shard/mesh/discretization.h>
#include <shard/particles/bond_failure.h>
#include <shard/particles/particle_set.h>
#include <shard/particles/spg_force.h>

#include <vector>

namespace shard::coupling
{
  /**
   * @brief Converts elements to particles during the run (doc/manual/hybrid.md, "Conversion
   * during the run"), after the force of a step and before its kick, so that stresses, history
   * and d all belong to the end of the step.
   *
   * 1. The volume-weighted stress and history of the converted elements go to their nodes
   *    (weight V_e / 8).
   * 2. The elements are removed; the particle set, its stencils and ghost set are rebuilt; when
   *    the layout of the DOFs changes, every state vector moves to it (owned values kept).
   * 3. Every owned particle keeps its history, or gets the volume average of what it had and
   *    what its newly converted cells bring, h = (V_old h_old + sum V_e/8 h_e) / V_new.
   * 4. F of the new stencils from the current coefficients; particles that existed keep their
   *    relative volume (SpgForce::volume_factor).
   * The stored elastic energy of the converted points changes (Material::elastic_energy_density
   * before and after); the caller books it with the jump of the stabilization energy.
   */
  class ElementConverter
  {
  public:
    /// The components a conversion rebuilds (owned by Simulation).
    struct Components
    {
      Conversion                        &conversion;
      mesh::Discretization              &discretization;
      const materials::MaterialLibrary &materials;
      particles::ParticleSet            &particles;
      particles::BondFailure            &bonds;
      fe::HexForce                      &hex;
      particles::SpgForce               &spg;
      const bc::BoundaryConditions      &conditions;
      const base::PrmSource             &source;
    };

    /// What a conversion did (sums over ranks unless said otherwise).
    struct Result
    {
      /// Cells converted by this call (0: nothing happened, nothing was rebuilt).
      unsigned long long added = 0;
      /// Elastic energy estimate of the converted points before and after (J).
      double elastic_before = 0, elastic_after = 0;
      /// This rank's particle stabilization energy of the new stencils (J).
      double stabilization = 0;
    };

    explicit ElementConverter(const Components &components)
      : c_(components)
    {}

    /**
     * @brief Converts the local elements @p elements of every rank.
     * @param vectors every vector of the state (moved to the new layout); @p d and @p v are
     *        among them and get their ghost values
     * @note Collective.
     */
    Result
    convert(const std::vector<unsigned int> &elements, const std::vector<mesh::Vector *> &vectors, mesh::Vector &d,
            mesh::Vector &v);

  private:
    Components c_;
  };
} // namespace shard::coupling
