// SPDX-License-Identifier: LGPL-2.1-or-later
/**
 * @file spg_force.h
 * @brief Internal force of the particles: two-level kinematics, material update per batch,
 *        nodal integration, stabilization and gradient correction. Subsection
 *        `F - Particle formulation`.
 * @ingroup particles
 */
#pragma once

#include <shard/base/parameters.h>
#include <shard/base/instability.h>
#include <shard/base/keyed_records.h>
#include <shard/materials/material_library.h>
#include <shard/materials/point_states.h>
#include <shard/particles/consistent_correction.h>
#include <shard/particles/particle_set.h>
#include <shard/particles/spg_operator.h>

#include <array>
#include <functional>
#include <map>
#include <string>
#include <vector>

namespace shard::particles
{
  /// What one particle force evaluation returns.
  struct ParticleForceResult
  {
    /// Smallest L_I / c_I of the owned particles (s).
    double stable_dt = 1e300;
    /// Stress work of this step, owned particles (J).
    double internal_energy = 0.;
    /// R2 energy W_s at the end of the step, owned particles (J).
    double stabilization_energy = 0.;
  };

  /**
   * @brief Owns the particle state (F, stress, material history per owned particle) and
   * computes the particle forces into the one force vector.
   *
   * The stress update is the same hypo-elastic path as the hexahedra: the strain increment
   * and spin come from dF F_mid^-1, the stored Cauchy stress is rotated by Hughes-Winget,
   * and the material is called once per batch of 64 particles. The force is the
   * total-Lagrangian f = A^T G^T (V P) with P = J sigma F^-T.
   */
  class SpgForce : public base::ParameterOwner
  {
  public:
    bool
    declare_parameters(dealii::ParameterHandler &prm) override;

    void
    check_parameters(const base::PrmSource &source) const override;

    /**
     * @brief Builds the particle state, the residual weights and the gradient correction.
     * @note Collective.
     */
    void
    prepare(const mesh::Discretization &discretization, ParticleSet &particles,
            const materials::MaterialLibrary &library);

    /// History of one particle kept across a rebuild (conversion during the run).
    struct SavedParticle
    {
      /// Reference volume V_I before the rebuild (m^3).
      double volume = 0;
      /// Bulk viscosity of the last step (Pa).
      double q = 0;
      /// Relative volume J = c det F of the last force evaluation (1).
      double jacobian = 1;
      /// Volume factor c (1), see set_volume_factor().
      double volume_factor = 1;
      /// Residual of the stabilization at the last evaluation, d - A d - r0 (m), and the
      /// offset r0 of its row (m), see SpgOperator::rebase_residual().
      std::array<double, 3> residual{}, residual_offset{};
      /// Cauchy stress (Pa).
      std::array<double, 6> stress{};
      /// History slots (material order).
      std::vector<double> state;
    };

    /// The history of every owned particle, by global particle id.
    std::map<unsigned long long, SavedParticle>
    save_state() const;

    /// Sets stress, history slots (material order) and bulk viscosity of owned particle @p i.
    void
    set_state(unsigned int i, const double *stress, const double *history, double q);

    /**
     * @brief The checkpoint of every owned particle, by @p key_of(i) (a key independent of the
     * partition): stress (6), q, history slots, volume factor, residual offset (3).
     */
    base::KeyedRecords
    portable_state(const std::function<unsigned long long(unsigned int)> &key_of) const;

    /**
     * @brief Restart: every owned particle @p i takes what portable_state() wrote under
     * @p key_of(i), on whichever rank that was.
     * @throws std::runtime_error when a particle is missing or has another number of values
     */
    void
    restore_portable(const base::KeyedLookup &saved, const std::function<unsigned long long(unsigned int)> &key_of);

    /**
     * @brief After the stencils were rebuilt (a conversion): the residual stabilization of
     * every owned particle continues from the residual it had in @p saved (zero for a particle
     * that is new), so that its energy does not jump (SpgOperator::rebase_residual()).
     * @param d the coefficients (ghost values set)
     */
    void
    keep_residuals(const mesh::Vector &d, const std::map<unsigned long long, SavedParticle> &saved);

    /// Sets the residual offset r0 of owned particle @p i (restart).
    void
    set_residual_offset(unsigned int i, const double *r0)
    {
      op_.set_residual_offset(i, r0);
      evaluated_ = false;
    }

    /**
     * @brief Sets the stored deformation gradient and physical displacement from the current
     * coefficients @p d (ghost values set), e.g. after a rebuild of the stencils, so that the
     * next increment F_new F_old^-1 does not see the change of the stencils.
     * @return the residual-stabilization energy W_s of the owned particles for @p d (J; 0
     *         without the residual stabilization)
     */
    double
    reset_deformation(const mesh::Vector &d);

    /**
     * @brief After the stencils changed in place (bonds broke at the end of a step): sets F and
     * u from the current coefficients @p d (ghost values set) like reset_deformation(), and
     * adds to @p delta (owned and ghost entries; compress(add) afterwards) the change of this
     * step's particle force, new minus old, with the stored stress. So the kick that follows
     * uses forces of the new stencils, and the work of the next step matches them.
     *
     * Right after add_internal_forces() (same @p d, stress and stencil pattern) only the rows
     * @p a_rows of A and @p g_rows of G that changed, and what they reach, are recomputed
     * (SpgOperator::refresh_internal_force(), the same numbers); otherwise everything is.
     * @param a_rows, g_rows the local rows rebuilt since the force (ParticleSet::take_rebuilt_rows())
     * @return the residual-stabilization energy W_s for @p d with the new stencils (J)
     */
    double
    refresh_forces(const mesh::Vector &d, mesh::Vector &delta, const std::vector<unsigned int> &a_rows,
                   const std::vector<unsigned int> &g_rows);
    /// Relative volume J = c_I det F of owned particle @p i at the last force evaluation or
    /// reset_deformation() (1); c_I is the volume factor below.
    double
    jacobian(unsigned int i) const;

    /**
     * @brief Sets the volume factor c_I of owned particle @p i (restart, conversion). c_I is 1
     * at set-up. When bonds break, the rebuilt rows give another F at the same coefficients;
     * c_I takes the jump of det F, so that the relative volume J = c_I det F the material sees
     * (pressure, density, volume of the force) stays continuous across the rebuild and the
     * stored elastic energy does not jump (doc/manual/failure.md).
     */
    void
    set_volume_factor(unsigned int i, double c)
    {
      volume_factor_[i] = c;
      evaluated_        = false;
    }

    /// Stable step estimate from the stored F and the initial wave speed (s). @note Collective.
    double
    current_stable_dt() const;

    /// Owned particle with the smallest stable step at the last force evaluation.
    unsigned int
    smallest_step_particle() const
    {
      return smallest_step_;
    }

    /// "particle <global id> of body '<name>' (reference position x, y, z) m" for owned particle @p i.
    std::string
    describe(unsigned int i) const;

    /// Smallest L_I / c over the owned particles at t = 0 (collective).
    double
    initial_stable_dt() const;

    /**
     * @brief R1, at the exchange point of a filter step: replaces the owned coefficients and
     * velocities by A d and A v (ghost values of @p d and @p v must be current; the caller
     * exchanges again afterwards).
     * @param f the total force of the last step, to estimate the internal-energy change
     * @return the energy the filter added on this rank (J; negative when it dissipates)
     */
    double
    filter(const mesh::Vector &mass, const mesh::Vector &f, mesh::Vector &d, mesh::Vector &v);

    /// Whether step @p step is a filter step.
    bool
    is_filter_step(unsigned int step) const
    {
      return active_ && options_.stabilization == Stabilization::filter && step % options_.filter_interval == 0;
    }

    /**
     * @brief Adds the particle forces at the end of the step into @p f (owned and ghost
     * entries; compress(add) afterwards) and updates the particle state.
     * @param d coefficients at the end of the step, ghost values set
     * @param dt step size
     * @throws Instability on an inverted particle (det F <= 0) or a non-finite stress.
     */
    ParticleForceResult
    add_internal_forces(const mesh::Vector &d, double dt, unsigned int step, mesh::Vector &f);

    /**
     * @brief Writes the physical displacement u_I = (A d)_I of the last force evaluation into
     * the owned particle entries of @p out (other entries untouched).
     */
    void
    physical_displacement(mesh::Vector &out) const;

    /// Physical displacements u_J = (A d)_J of the last force evaluation over the rows J of the
    /// local stencils (owned first, then the first ring; 3 each).
    const std::vector<double> &
    displacement_rows() const
    {
      return u_;
    }
    /// Deformation gradient of owned particle @p i at the last force evaluation (9, row-major).
    const double *
    deformation_gradient(unsigned int i) const
    {
      return &F_[9 * i];
    }
    /// Whether there are particles.
    bool
    active() const
    {
      return active_;
    }

    /// Number of owned particles.
    unsigned int
    n_owned() const
    {
      return particles_ ? particles_->n_owned() : 0u;
    }

    /// Cauchy stress of owned particle @p i (6: xx yy zz yz xz xy).
    const double *
    stress(unsigned int i) const
    {
      return &stress_[6 * i];
    }

    /// A named state slot of owned particle @p i (0 if the material has no such slot).
    double
    state_value(unsigned int i, const std::string &name) const;

    /// History slots of owned particle @p i (material().state_slot_names() order).
    const double *
    state(unsigned int i) const;

    /// Material of owned particle @p i.
    const materials::Material &
    material(unsigned int i) const
    {
      return points_.material(i);
    }

    /// The particle set.
    const ParticleSet &
    particles() const
    {
      return *particles_;
    }

    /// The options.
    const FormulationOptions &
    options() const
    {
      return options_;
    }

    /// Outcome of the consistent-correction solve at set-up (zero iterations when not used).
    const CorrectionSolve &
    correction_solve() const
    {
      return correction_solve_;
    }

    /**
     * @brief Bytes of particle data this object owns on this rank: the state per owned
     * particle (F, stress, bulk viscosity, density, length, material history), the gather and
     * scratch arrays of the force evaluation and the SpgOperator (allocated capacities). The
     * ParticleSet and its stencils are not counted (ParticleSet::memory_consumption()).
     */
    std::size_t
    memory_consumption() const;

  private:
    unsigned int       smallest_step_      = 0;
    /// Bulk viscosity Q1, Q2 (`bulk viscosity linear`, `quadratic`).
    materials::BulkViscosity viscosity_{0.06, 1.5};
    std::string        smoothing_text_     = "two-level";
    std::string        stabilization_text_ = "residual";
    std::string        correction_text_    = "consistent";
    /// Aggregate edge of the correction solve's coarse space, in mean spacings (0: none).
    double correction_coarse_size_ = 3;
    FormulationOptions options_;
    bool               active_ = false;
    /// Whether u, F, VP, the force and the operator's g and residual weights are those of the
    /// last add_internal_forces() at the present d (a partial refresh may start from them).
    bool evaluated_ = false;

    const ParticleSet           *particles_ = nullptr;
    const mesh::Discretization  *discretization_ = nullptr;
    SpgOperator                  op_;
    CorrectionSolve              correction_solve_;
    /// Material groups, history and batches of the owned particles.
    materials::PointStates       points_;
    std::vector<double>          F_, stress_, q_, density_, length_;
    std::vector<double>          volume_factor_; // c_I: J = c_I det F (jumps of det F at rebuilt rows)
    mutable std::vector<double>  dk_, u_, fk_, Fnew_, VP_;
    std::vector<double>          work_; // stress and bulk-viscosity work per owned particle of the last step

    void
    gather(const mesh::Vector &v, std::vector<double> &out) const;
    /// u = A d and the stored F from the coefficients @p d (ghost values set).
    void
    set_kinematics(const mesh::Vector &d);

    /// Solves for the consistent gradient correction and writes G + C into the stencils of
    /// @p particles, which the operator reads (collective).
    void
    prepare_consistent_correction(ParticleSet &particles);

    [[noreturn]] void
    fail(unsigned int i, unsigned int step, const std::string &what) const;
  };
} // namespace shard::particles
