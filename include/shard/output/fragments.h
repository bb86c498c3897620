// SPDX-License-Identifier: LGPL-2.1-or-later
/**
 * @file fragments.h
 * @brief Fragments: connected components of the nodes through intact elements and particle
 *        bonds, with mass, centre of mass, velocity and kinetic energy (issue 6, first part),
 *        size and shape (equivalent diameter, aspect ratio), and the debris and dust
 *        classification with its summary (issue 26); doc/manual/failure.md, "Fragments".
 * @ingroup output
 */
#pragma once

#include <shard/fe/hex_force.h>
#include <shard/mesh/discretization.h>
#include <shard/particles/particle_set.h>

#include <array>
#include <string>
#include <vector>

namespace shard::output
{
  /**
   * @brief Mass moments of a set of nodes about a reference point @f$ a @f$ (the first node
   * added): @f$ M = \sum m_i @f$, @f$ V = \sum V_i @f$, @f$ P = \sum m_i (x_i - a) @f$,
   * @f$ Q = \sum m_i (x_i - a)(x_i - a)^T @f$ and the nodes' own spread
   * @f$ S = \sum m_i h_i^2 / 12 @f$, @f$ h_i = V_i^{1/3} @f$ (a node as a cube of its volume).
   * Sums about a point inside the fragment keep the cancellation of the centred moment at the
   * fragment's size, not at its distance from the origin. merge() shifts the other sums to
   * this reference, so the parts of a fragment on several ranks combine in any grouping.
   */
  struct MassMoments
  {
    /// Number of doubles of pack() and unpack().
    static constexpr unsigned int n_values = 16;

    /// Whether a node was added (then @ref reference is set).
    bool has_reference = false;
    /// @f$ M @f$ (kg), @f$ V @f$ (m^3), @f$ S @f$ (kg m^2).
    double mass = 0, volume = 0, own = 0;
    /// @f$ a @f$ (m) and @f$ P @f$ (kg m).
    std::array<double, 3> reference{}, first{};
    /// @f$ Q @f$ (kg m^2) in the order xx, yy, zz, yz, xz, xy.
    std::array<double, 6> second{};

    /// Adds a node at @p x (m) of mass @p m (kg) and volume @p V (m^3).
    void
    add(const std::array<double, 3> &x, double m, double V);

    /// Adds the sums of @p other (moved to this reference point).
    void
    merge(const MassMoments &other);

    /// Appends the n_values numbers of these sums to @p out.
    void
    pack(std::vector<double> &out) const;

    /// The sums packed at @p values by pack().
    static MassMoments
    unpack(const double *values);

    /**
     * @brief The mass covariance with the nodes' own spread,
     * @f$ C = (Q - P P^T / M) / M + (S / M) I
     *      = \frac{1}{M} \sum m_i \left[(x_i - c)(x_i - c)^T + \frac{h_i^2}{12} I\right] @f$
     * (m^2; xx, yy, zz, yz, xz, xy), zero without mass. For nodes on a lattice of spacing h
     * (node volume h^3) filling a box of n_1 x n_2 x n_3 nodes, C is the covariance of the solid
     * box n_1 h x n_2 h x n_3 h: @f$ C_{kk} = (n_k h)^2 / 12 @f$.
     */
    std::array<double, 6>
    covariance() const;
  };

  /// Size and shape of a fragment from its MassMoments.
  struct FragmentShape
  {
    /// Reference volume V (m^3).
    double volume = 0;
    /// Diameter of the sphere of volume V, @f$ (6 V / \pi)^{1/3} @f$ (m).
    double equivalent_diameter = 0;
    /// @f$ \sqrt{\lambda_{max} / \lambda_{min}} @f$ of the covariance (1 for a single node,
    /// n for a lattice rod of n nodes; 1 without mass, infinity for a zero smallest eigenvalue).
    double aspect_ratio = 1;
    /// Eigenvalues of the covariance, largest first (m^2).
    std::array<double, 3> principal_variances{};
  };

  /**
   * @brief Equivalent diameter and aspect ratio of @p moments (pure; no MPI): the eigenvalues
   * of MassMoments::covariance() (self-adjoint QR iteration, accurate for a small eigenvalue
   * beside a large one) and @f$ (6 V / \pi)^{1/3} @f$.
   */
  FragmentShape
  fragment_shape(const MassMoments &moments);

  /// One fragment: a connected set of nodes and particles.
  struct Fragment
  {
    /// Smallest coarse-mesh vertex index of the fragment's nodes: the same at any number of ranks.
    unsigned long long id = 0;
    /// Nodes (FE nodes and particles) and, of them, particles.
    unsigned long long nodes = 0, particles = 0;
    /// Mass (kg), centre of mass (m), velocity = momentum / mass (m/s), kinetic energy (J).
    double                mass = 0;
    std::array<double, 3> centre{}, velocity{};
    /// Origin: the centre of mass in the reference configuration, sum m_i X_i / M (m): where the
    /// fragment's material came from (crater or scab of a slab, say).
    std::array<double, 3> origin{};
    double                kinetic_energy = 0;
    /// Body index (cell material id): bodies share no nodes, so a fragment lies in one body.
    unsigned int body = 0;
    /// Reference volume: the sum of the lumped nodal volumes (V_e / 8 of every cell at the node),
    /// mass / rho0 for one material (m^3).
    double volume = 0;
    /// @f$ (6 V / \pi)^{1/3} @f$ (m) and the aspect ratio (1), see fragment_shape().
    double equivalent_diameter = 0, aspect_ratio = 1;
    /// Set by classify(): not the heaviest fragment of its body; debris of fewer than the dust
    /// threshold nodes; angle between the velocity and the debris axis (degrees, 0 at rest).
    bool   debris = false, dust = false;
    double cone_angle = 0;
  };

  /**
   * @brief Classifies @p fragments (pure; the same on every rank). Debris: every fragment
   * except the heaviest fragment of each body (masses within 1e-12 relative are a tie, won by
   * the smallest id), i.e. what broke off the
   * bodies. Dust: debris of fewer than @p dust_nodes nodes (particles and FE nodes; debris is
   * usually particles only). Cone angle: @f$ \operatorname{atan2}(|v \times a|, v \cdot a) @f$ in
   * degrees for the unit @p axis a (0 for a fragment at rest).
   */
  void
  classify(std::vector<Fragment> &fragments, unsigned int dust_nodes, const std::array<double, 3> &axis);

  /// Summary of classified fragments (summary.json, block `fragments`).
  struct FragmentSummary
  {
    /// Fragments, debris fragments, dust fragments.
    unsigned long long count = 0, debris_count = 0, dust_count = 0;
    /// Mass of all fragments, of the debris, of the dust (a part of the debris), of the debris
    /// that is not dust, of the fragments that are not debris (kg).
    double mass = 0, debris_mass = 0, dust_mass = 0, coarse_debris_mass = 0, body_mass = 0;
    /// dust_mass / debris_mass and coarse_debris_mass / debris_mass (0 without debris).
    double dust_fraction = 0, coarse_debris_fraction = 0;
    /// Largest debris mass (kg), fastest debris speed (m/s), median mass of the debris that is not
    /// dust (kg; the mean of the middle two for an even count; 0 without).
    double largest_debris_mass = 0, fastest_debris_speed = 0, median_coarse_debris_mass = 0;
    /// Over all debris (dust included), mass-weighted: mean cone angle and the 90 % cone angle,
    /// the smallest angle within which at least 90 % of the debris mass moves (degrees; 0 without).
    double cone_angle_mean = 0, cone_angle_90 = 0;
  };

  /// The summary of @p fragments after classify() (pure).
  FragmentSummary
  summarize(const std::vector<Fragment> &fragments);

  /**
   * @brief The `fragments` object of summary.json (one line, no trailing comma): time, count,
   * mass, the classification settings and the summary of @p fragments (after classify()), with
   * 17 significant digits so that the masses add up to the total to round-off.
   */
  std::string
  summary_json(const std::vector<Fragment> &fragments, double time, unsigned int dust_particles,
               const std::array<double, 3> &axis);

  /**
   * @brief Finds the fragments: two nodes are connected when an intact element holds both or
   * when one particle lies in the RK stencil of the other (a bond). Bodies never share nodes,
   * so without failure every connected body is one fragment. prepare() joins the owned and
   * ghost nodes of this rank into local components (union-find over the edges); compute()
   * gives every local component the smallest coarse-mesh vertex index among its nodes and lets the
   * owners combine ghost labels by min, until no label changes on any rank. So 1 and 2 ranks
   * give the same fragments, and a sweep costs one pass over the nodes.
   */
  class Fragments
  {
  public:
    /// Collects the edges of the owned elements and particle rows, and the body and lumped
    /// volume of every owned node. Call again after a rebuild. @note Collective.
    void
    prepare(const mesh::Discretization &discretization, const fe::HexForce &hex,
            const particles::ParticleSet &particles);

    /**
     * @brief The fragments, sorted by id, on rank 0 (empty on the other ranks: only rank 0
     * writes the tables), with their body, volume, equivalent diameter and aspect ratio
     * (positions X + d; MassMoments per rank, merged in rank order); not classified
     * (classify()).
     * @param d physical displacement (ghost values not needed)
     * @param v velocity
     * @param mass lumped mass
     * @note Collective.
     */
    std::vector<Fragment>
    compute(const mesh::Vector &d, const mesh::Vector &v, const mesh::Vector &mass) const;

  private:
    const mesh::Discretization *discretization_ = nullptr;
    /// Local components: first local DOF of every owned or ghost node, grouped by component
    /// (members of component c at [offsets_[c], offsets_[c + 1])).
    std::vector<unsigned int> members_, offsets_;
    /// Coarse-mesh vertex index of every owned node (by first local DOF / 3).
    std::vector<unsigned int> node_id_;
    /// 1 for owned nodes that are particles (by first local DOF / 3).
    std::vector<unsigned char> particle_;
    /// Body index of every owned node (by first local DOF / 3).
    std::vector<unsigned int> body_;
    /// Lumped reference volume of every owned node: V_e / 8 of each cell at it (by first local DOF / 3).
    std::vector<double> volume_;
  };
} // namespace shard::output
