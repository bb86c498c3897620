// SPDX-License-Identifier: LGPL-2.1-or-later
/**
 * @file conversion.h
 * @brief Element-to-particle conversion: predicted-failure regions converted at set-up and
 *        elements converted during the run when they meet a criterion (formulation.md section 7,
 *        node-based scheme). Subsection `G - Conversion`.
 * @ingroup coupling
 */
#pragma once

#include <shard/base/parameters.h>
#include <shard/mesh/discretization.h>

#include <algorithm>
#include <array>
#include <functional>
#include <map>
#include <memory>
#include <string>
#include <vector>

namespace shard::fe
{
  class HexForce;
}

namespace shard::coupling
{
  /// Parameters of one predicted-failure region (subsection `G - Conversion/<name>`).
  struct RegionParameters
  {
    /// Region name (the subsection name).
    std::string name;
    /// Body the region applies to (name from `B - Mesh/body names`).
    std::string body;
    /// box, cylinder, sphere, half-space or body (every element of the body).
    std::string shape = "box";
    /// Box: corners "x, y, z" (m).
    std::string lower_corner = "0, 0, 0", upper_corner = "0.1, 0.1, 0.1";
    /// Sphere: centre; cylinder: centre of the start face; half-space: a point on the plane (m).
    std::string centre = "0, 0, 0";
    /// Sphere and cylinder radius (m).
    double radius = 0.;
    /// Cylinder: axis direction; half-space: normal pointing into the region.
    std::string direction = "0, 0, 1";
    /// Cylinder length along its axis from the centre of the start face (m).
    double length = 0.;
  };

  /**
   * @brief Geometric test of a region on a point (deal.II-free, so unit tests need no mesh).
   */
  class Region
  {
  public:
    /// Shapes a region may have.
    enum class Shape
    {
      box,
      cylinder,
      sphere,
      half_space,
      body
    };

    /// Builds the test from parsed parameters; throws std::invalid_argument on bad geometry.
    Region(const RegionParameters &p, int body);

    /// Whether @p x (a cell centre in the reference configuration, m) lies in the region.
    bool
    contains(const std::array<double, 3> &x) const;

    /// Body index the region applies to.
    int
    body() const
    {
      return body_;
    }

  private:
    Shape                 shape_;
    int                   body_;
    std::array<double, 3> a_{}, b_{}, direction_{};
    double                radius_ = 0, length_ = 0;
  };

  /**
   * @brief Smallest ratio over the eight corners of a hexahedron of the corner Jacobian in the
   * current configuration to that in the reference one (deal.II vertex order; 1 for a rigid
   * motion, <= 0 for a corner that folded over).
   */
  double
  min_corner_jacobian_ratio(const double (&x)[8][3], const double (&X)[8][3]);

  /**
   * @brief Decides which hexahedra become particles: the cells of the predicted-failure regions
   * at set-up and, during the run, elements of the adaptive bodies that meet a criterion.
   *
   * The converted set is a set of coarse-cell ids known on every rank (shard's cells are all
   * on level 0), so owned and ghost cells carry the same flag on every rank. The history
   * transfer itself is done by the Simulation through HexForce and SpgForce; this class keeps
   * the set, the criteria and the event counters.
   */
  class Conversion : public base::ParameterOwner
  {
  public:
    bool
    declare_parameters(dealii::ParameterHandler &prm) override;

    void
    check_parameters(const base::PrmSource &source) const override;

    /**
     * @brief Resolves the regions and flags the cells converted at set-up: every cell of the
     * bodies in @p particle_bodies (`E - Particles/bodies`) and the cells whose reference centre
     * lies in a region.
     * @throws base::InputError (through @p source) for an unknown body name.
     */
    void
    prepare(const mesh::Discretization &discretization, const std::vector<std::string> &particle_bodies,
            const base::PrmSource &source);

    /**
     * @brief The rule of prepare() as a function of a cell's body and reference centre, for the
     * first partition, made before the mesh exists (Discretization::prepare() weights the cells
     * by it). Needs only the bodies of @p discretization (`bodies()`), not its cells.
     * @throws base::InputError (through @p source) for an unknown body name.
     */
    std::function<bool(unsigned int body, const std::array<double, 3> &centre)>
    converted_at_setup(const mesh::Discretization &discretization, const std::vector<std::string> &particle_bodies,
                       const base::PrmSource &source) const;

    /// Flag per active cell index (owned and ghost cells): converted to particles.
    const std::vector<bool> &
    converted_cells() const
    {
      return converted_;
    }

    /// Number of converted cells over all ranks.
    unsigned long long
    n_converted() const
    {
      return n_converted_;
    }

    /// Whether elements may convert during the run.
    bool
    adaptive() const
    {
      return !adaptive_bodies_.empty();
    }

    /// Indices of the bodies whose elements may convert during the run.
    const std::vector<unsigned int> &
    adaptive_bodies() const
    {
      return adaptive_bodies_;
    }

    /// Whether the criteria are checked after step @p step.
    bool
    is_check_step(const unsigned int step) const
    {
      return adaptive() && step % check_interval_ == 0;
    }

    /**
     * @brief Local elements of @p hex (owned, unconverted) that meet a criterion: effective
     * plastic strain, K&C scaled damage, smallest corner Jacobian ratio (current over
     * reference) or element time step below the floor. Only elements of adaptive bodies count,
     * and, when 'adaptive regions' are named, only those whose reference centre lies in one.
     * @param d displacement with ghost values (for the corner Jacobians)
     */
    std::vector<unsigned int>
    candidates(const fe::HexForce &hex, const mesh::Vector &d) const;

    /**
     * @brief Adds the active cells @p cells (owned here) of every rank to the converted set
     * and updates the flags of owned and ghost cells.
     * @return the number of cells added over all ranks
     * @note Collective.
     */
    unsigned long long
    add_cells(const std::vector<unsigned int> &cells);

    /// Number of conversion events during the run (not counting the set-up).
    unsigned int
    n_events() const
    {
      return n_events_;
    }

    /**
     * @brief Restart: replaces the converted set by the cells @p cells (coarse cell ids, sorted,
     * the same list on every rank; each rank flags those it holds, own and ghost) and the event
     * count by @p n_events. Call after prepare() and before the particle set is built.
     */
    void
    restore(const std::vector<std::uint64_t> &cells, unsigned int n_events)
    {
      std::fill(converted_.begin(), converted_.end(), false);
      for (const auto &cell : discretization_->triangulation().active_cell_iterators())
        if (!cell->is_artificial() &&
            std::binary_search(cells.begin(), cells.end(), cell->id().get_coarse_cell_id()))
          converted_[cell->active_cell_index()] = true;
      n_converted_ = cells.size();
      n_events_    = n_events;
    }

  private:
    /// The set-up regions of prepare(): every particle body whole, then the named regions.
    std::vector<Region>
    setup_regions(const mesh::Discretization &discretization, const std::vector<std::string> &particle_bodies,
                  const base::PrmSource &source) const;

    std::string                                               region_names_text_;
    std::vector<std::string>                                  region_names_;
    std::map<std::string, std::unique_ptr<RegionParameters>> declared_;
    bool                                                      declared_main_ = false;
    std::string                                               adaptive_bodies_text_;
    std::vector<unsigned int>                                 adaptive_bodies_;
    /// 'adaptive regions': the names (empty: the whole adaptive bodies).
    std::string                                               adaptive_region_names_text_;
    std::vector<std::string>                                  adaptive_region_names_;
    /// The names of 'regions' and 'adaptive regions', in that order (each has a subsection).
    std::vector<std::string>
    all_region_names() const;
    double                                                    plastic_strain_ = 0., scaled_damage_ = 0.;
    double                                                    min_jacobian_ = 0., dt_floor_ = 0.;
    unsigned int                                              check_interval_ = 1;

    const mesh::Discretization *discretization_ = nullptr;
    std::vector<bool>           converted_;
    /// Per active cell: whether it may convert during the run (an adaptive body's cell whose
    /// reference centre lies in an adaptive region, or any such cell without adaptive regions).
    std::vector<bool>           adaptive_cell_;
    unsigned long long          n_converted_ = 0;
    unsigned int                n_events_    = 0;
  };
} // namespace shard::coupling
