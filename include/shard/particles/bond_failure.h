// SPDX-License-Identifier: LGPL-2.1-or-later
/**
 * @file bond_failure.h
 * @brief Failure of particle bodies by bond breaking: per-material criteria, the comparison
 *        rule, free particles. Subsection `E - Particles/bond failure`.
 * @ingroup particles
 *
 * Theory, parameters and validation: doc/manual/failure.md.
 */
#pragma once

#include <shard/base/parameters.h>
#include <shard/materials/material_library.h>
#include <shard/mesh/discretization.h>
#include <shard/particles/particle_set.h>
#include <shard/particles/spg_force.h>

#include <map>
#include <set>
#include <string>
#include <vector>

namespace shard::particles
{
  /// The particle value a material's bonds are judged by.
  enum class BondCriterion
  {
    /// No material criterion (the stretch criterion may still apply).
    none,
    /// Effective plastic strain (history slot "effective plastic strain"), unit 1.
    plastic_strain,
    /// K&C scaled damage (history slot "scaled damage", 0 to 2), unit 1.
    scaled_damage,
    /// Largest principal Cauchy stress, Pa.
    principal_stress,
    /// Largest principal engineering strain, sqrt(largest eigenvalue of F^T F) - 1, unit 1.
    principal_strain
  };

  /// Which particle values of a bond are compared with the threshold.
  enum class BondRule
  {
    /// The mean of the two normalized values q_I / q_c,I and q_J / q_c,J reaches 1.
    mean,
    /// Either end reaches its threshold.
    either,
    /// Both ends reach their thresholds.
    both,
    /// The mean reaches 1 and the bond is stretched, |x_J - x_I| > |X_J - X_I|: a crack opens
    /// across the bond; compressed bonds of crushed material hold.
    tension
  };

  /**
   * @brief Breaks bonds between particles for good when a criterion is met (formulation.md
   * section 5) and turns particles left with too few bonds into free particles.
   *
   * A bond is a pair (I, J) with J in the support of I's RK functions (an entry of the G
   * stencil of row I). Every particle has a normalized failure value q^_I = q_I / q_c of its
   * material's criterion (0 without one) and a critical stretch s_I (0 without one). At a check
   * step, after the force of the step:
   * 1. every rank writes q^ and s of its owned particles into a vector and exchanges its ghost
   *    values, so that both ends of every local bond see the same numbers;
   * 2. every rank tests the bonds of its owned rows: the rule (mean, either, both) on q^ and
   *    the stretch lambda = |X_J + u_J - X_I - u_I| / |X_J - X_I| against min(s_I, s_J),
   *    breaking when lambda > s or lambda < 1 / s, and the opening |x_J - x_I| - |X_J - X_I|
   *    against the critical crack opening min(w_I, w_J) (a crack across the bond has opened
   *    fully; a compressed bond never breaks by it);
   * 3. the new bonds go point to point to the ranks that hold rows with them
   *    (ParticleSet::spread_bonds: the owners of both ends, then the ranks that hold those
   *    particles), which rebuild the rows from the surviving bonds; no rank holds a global list;
   * 4. owned particles whose relative volume J fell below their material's `minimum volume
   *    ratio` (crushed), and then those with fewer than `minimum bonds` intact bonds, become
   *    free: all their bonds break, on the ranks that hold them (ParticleSet::spread_free);
   *    repeated until no particle becomes free.
   * Mass, momentum, stress and history of every particle stay as they are. A free particle
   * has the identity as A row and a zero G row: no internal force, it moves with its
   * velocity until contact stops it.
   */
  class BondFailure : public base::ParameterOwner
  {
  public:
    /// @param library the materials, whose names give the per-material subsections
    explicit BondFailure(const materials::MaterialLibrary &library);

    bool
    declare_parameters(dealii::ParameterHandler &prm) override;

    void
    check_parameters(const base::PrmSource &source) const override;

    /**
     * @brief Resolves the criterion, threshold and critical stretch of every owned particle
     * from its material. Call again after a rebuild of the particle set.
     * @throws base::InputError naming the key if a criterion needs a history slot the
     *         material does not have (e.g. plastic strain of an elastic material).
     */
    void
    prepare(ParticleSet &particles, const SpgForce &spg, const base::PrmSource &source);

    /// Whether any material has a criterion and there are particles.
    bool
    active() const
    {
      return active_;
    }

    /// Whether bonds are tested at the end of step @p step.
    bool
    is_check_step(unsigned int step) const
    {
      return active_ && step % check_interval_ == 0;
    }

    /**
     * @brief Tests the bonds and breaks those that fail, then frees particles with too few
     * bonds (steps 1 to 4 above). @p q is work space with the layout of the Discretization.
     * @return the number of bonds broken and of particles freed in this call, over all ranks
     * @note Collective.
     */
    std::pair<unsigned long long, unsigned long long>
    update(const mesh::Discretization &discretization, ParticleSet &particles, const SpgForce &spg, mesh::Vector &q);

    /// Bonds broken so far (all ranks).
    unsigned long long
    n_broken() const
    {
      return n_broken_;
    }

    /// Free particles so far (all ranks).
    unsigned long long
    n_free() const
    {
      return n_free_;
    }

    /// Bytes this rank sent in the last update() (failure values, bonds and free particles; base::Traffic).
    double
    bytes_sent() const
    {
      return bytes_sent_;
    }

    /// Condition limit of rows rebuilt after bonds broke (`condition limit`). Unit: 1.
    double
    condition_limit() const
    {
      return condition_limit_;
    }

    /// Restart: the counts of broken bonds and free particles of a checkpoint.
    void
    restore_counts(const unsigned long long n_broken, const unsigned long long n_free)
    {
      n_broken_ = n_broken;
      n_free_   = n_free;
    }

    /// The normalized failure value q_I / q_c of owned particle @p i at the last update (0 without a criterion).
    double
    value(unsigned int i) const
    {
      return i < value_.size() ? value_[i] : 0.;
    }

  private:
    struct Settings
    {
      std::string criterion_text = "none";
      double      threshold      = 0;
      double      stretch        = 0;
      double      opening        = 0;
      double      volume_ratio   = 0;
    };
    const materials::MaterialLibrary &library_;
    std::map<std::string, Settings>   settings_;
    std::set<std::string>             declared_materials_;
    bool                              declared_       = false;
    bool                              active_         = false;
    unsigned int                      check_interval_ = 1;
    std::string                       rule_text_      = "mean";
    BondRule                          rule_           = BondRule::mean;
    unsigned int                      minimum_bonds_  = 3;
    double                            condition_limit_ = 1e-2;
    unsigned long long                n_broken_ = 0, n_free_ = 0;
    double                            bytes_sent_ = 0;
    /// Per owned particle: criterion, threshold, critical stretch, history slot (-1: none).
    std::vector<BondCriterion> criterion_;
    std::vector<double>        threshold_, stretch_, opening_, value_, volume_ratio_;
    std::vector<int>           slot_;
    /// Per owned particle: whether it still has an intact bond (its value is exchanged as 0
    /// otherwise, so that free particles do not keep the largest value up).
    std::vector<unsigned char> has_bonds_;
    /// Whether some material has a critical stretch (then no row can be skipped by its value).
    bool stretch_possible_ = false;

    /// The normalized failure value of owned particle @p i now.
    double
    evaluate(const SpgForce &spg, unsigned int i) const;
  };

} // namespace shard::particles
