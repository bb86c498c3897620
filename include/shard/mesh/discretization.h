// SPDX-License-Identifier: LGPL-2.1-or-later
/**
 * @file discretization.h
 * @brief Bodies, their meshes, the distributed triangulation and the degrees of freedom.
 * @ingroup mesh
 */
#pragma once

#include <shard/base/parameters.h>

#include <deal.II/base/partitioner.h>
#include <deal.II/distributed/fully_distributed_tria.h>
#include <deal.II/dofs/dof_handler.h>
#include <deal.II/fe/fe_system.h>
#include <deal.II/lac/la_parallel_vector.h>

#include <array>
#include <functional>
#include <map>
#include <memory>
#include <set>
#include <string>
#include <vector>

namespace shard::mesh
{
  /// Distributed vector type used for every state vector.
  using Vector = dealii::LinearAlgebra::distributed::Vector<double>;

  /**
   * @brief Parameters of one body: its mesh, material and initial velocity
   * (subsection `B - Mesh/<name>`).
   */
  struct BodyParameters
  {
    /// Body name (the subsection name).
    std::string name;
    /// Mesh shape: box, rod, cylinder, ogive or gmsh.
    std::string shape = "box";
    /// Box: lower corner "x, y, z" (m).
    std::string lower_corner = "0, 0, 0";
    /// Box: upper corner "x, y, z" (m).
    std::string upper_corner = "0.1, 0.01, 0.01";
    /// Rod and cylinder: length along the axis (m).
    double length = 0.1;
    /// Rod: side of the square cross-section (m).
    double width = 0.01;
    /// Cylinder: radius (m).
    double radius = 0.005;
    /// Box: growth ratio of the element size outside the fine core (1: uniform).
    double grading = 1.;
    /// Box with grading: lower corner of the fine core "x, y, z" (m); empty: the whole box.
    std::string fine_lower_corner;
    /// Box with grading: upper corner of the fine core "x, y, z" (m); empty: the whole box.
    std::string fine_upper_corner;
    /// Ogive: radius of the nose arc in calibers (diameters), the CRH; 0.5 is a hemisphere.
    double nose_crh = 3.;
    /// Ogive: radius of the flat tip (meplat) as a fraction of the radius, in (0, 1).
    double nose_tip = 0.25;
    /// Rod and cylinder: axis direction x, y or z.
    std::string axis = "z";
    /// Rod and cylinder: centre of the start face; gmsh: translation (m).
    std::string origin = "0, 0, 0";
    /// Target element size (m); 0 uses `refinement`.
    double element_size = 0.;
    /// Global refinement level when element size is 0 (box and rod: 2^level cells per edge).
    unsigned int refinement = 2;
    /// Gmsh: mesh file, relative to the .prm file's directory.
    std::string mesh_file;
    /// Gmsh: factor applied to the file's coordinates to get metres.
    double mesh_scale = 1.;
    /// Material name from `C - Materials`.
    std::string material = "steel";
    /// Initial velocity: three muparser expressions of x, y, z separated by ';' (m/s).
    std::string initial_velocity = "0; 0; 0";
  };

  /**
   * @brief Length of the nose of the `ogive` shape: a tangent ogive of arc radius
   * 2 @p radius @p crh cut where its radius is @p tip times @p radius (m).
   */
  double
  ogive_nose_length(double radius, double crh, double tip);

  /**
   * @brief Cell sizes along one edge of a graded `box`: uniform cells of at most @p h in the
   * fine core [@p fine_lower, @p fine_upper] (clipped to [@p lower, @p upper]), and on either
   * side cells that grow from the core's cell size by the factor @p ratio per cell, scaled down
   * together so that they fill the side exactly (m, in order from @p lower). With @p ratio = 1
   * every cell is uniform over the whole edge.
   * @pre lower < upper, h > 0, ratio >= 1.
   */
  std::vector<double>
  graded_cell_sizes(double lower, double upper, double fine_lower, double fine_upper, double h, double ratio);

  /**
   * @brief Exact volume of the `ogive` shape of total length @p length: the cut ogive nose
   * (a solid of revolution, closed form) and the cylindrical shank (m^3).
   */
  double
  ogive_volume(double radius, double length, double crh, double tip);

  /**
   * @brief Outward area vector of face @p f of @p cell: half the cross product of the face
   * diagonals (exact for planar quadrilaterals), oriented away from the cell centre.
   */
  dealii::Tensor<1, 3>
  outward_area_vector(const dealii::DoFHandler<3>::active_cell_iterator &cell, unsigned int f);

  /**
   * @brief Nodal outward area vectors of face @p f of @p cell: int N_v n dA for each face vertex
   * v (deal.II face vertex order), N_v the bilinear face shape functions; 2x2 Gauss, exact for
   * bilinear faces. Unlike a quarter of outward_area_vector(), they integrate linear functions
   * exactly on any bilinear face: sum_v a_v (x) X_v = int x (x) n dA.
   */
  std::array<dealii::Tensor<1, 3>, 4>
  nodal_area_vectors(const dealii::DoFHandler<3>::active_cell_iterator &cell, unsigned int f);

  /**
   * @brief Owns the bodies, the distributed triangulation, the Q1 vector element and the DoFs.
   *
   * All bodies are meshed in serial on rank 0 and merged into one mesh (the model's cells in
   * input order; vertices are not merged across bodies). Rank 0 orders the cells body by body,
   * each body along a Hilbert curve through its cell centres, cuts that order into contiguous
   * ranges (by count, or by work with particles at set-up) and sends each rank its own cells and
   * the layer of cells that share a vertex with them; every rank then holds only that part, as a
   * `parallel::fullydistributed::Triangulation` (doc/manual/cluster.md, "The distributed
   * mesh"). Every cell is a coarse cell; its coarse cell id is its index in the merged mesh, and
   * vertex_key() gives a vertex's index there: both are the same at any rank count. Cell
   * material id = body index; each body keeps its own boundary ids. The three DOFs of a vertex
   * are consecutive and owned by one rank (checked in prepare()).
   */
  class Discretization : public base::ParameterOwner
  {
  public:
    /// @param comm communicator of the run.
    explicit Discretization(MPI_Comm comm);

    bool
    declare_parameters(dealii::ParameterHandler &prm) override;

    void
    check_parameters(const base::PrmSource &source) const override;

    /// Whether the cell of body `body` with reference centre `centre` becomes particles at set-up.
    using SetupConversion = std::function<bool(unsigned int body, const std::array<double, 3> &centre)>;

    /**
     * @brief Builds the meshes, the triangulation, DoFs, partitioner and reference positions.
     *
     * With more than one rank and `particle weight` > 0, the partition is weighted by work: 1 per
     * element, `particle weight` per particle, a cell converted at set-up (by the rule that
     * @p conversion returns, given the bodies) carrying 1/n of each of its nodes (n = converted
     * cells at the node). Rank 0 computes the weights on the serial mesh, so no repartition
     * follows.
     * @param source for relative mesh paths and error messages.
     * @param conversion makes the set-up conversion rule once the bodies are known (empty: none).
     * @note Collective.
     */
    void
    prepare(const base::PrmSource &source,
            const std::function<SetupConversion(const Discretization &)> &conversion = {});

    /**
     * @brief The imbalance (largest over mean owned work) that the partition by cell count
     * would have had, when prepare() weighted the partition; else 0.
     */
    double
    imbalance_by_count() const
    {
      return imbalance_by_count_;
    }

    /// Default of `B - Mesh/particle weight`: the measured cost of a particle in units of an
    /// element (phase 6 / phase 5 per item, doc/performance.md "MPI scaling").
    static constexpr double default_particle_weight = 1.5;

    /// `B - Mesh/particle weight`: cost of a particle in units of an element.
    double
    particle_weight() const
    {
      return particle_weight_;
    }

    /// The bodies in input order (body index = cell material id).
    const std::vector<BodyParameters> &
    bodies() const
    {
      return bodies_;
    }

    /// Index of body @p name, or -1.
    int
    body_index(const std::string &name) const;

    /// The triangulation type: each rank holds its own cells and one layer of ghost cells.
    using Triangulation = dealii::parallel::fullydistributed::Triangulation<3>;

    /// The distributed triangulation (own cells and the ghost layer only).
    const Triangulation &
    triangulation() const
    {
      return triangulation_;
    }

    /// DoF handler of FESystem(FE_Q(1), 3).
    const dealii::DoFHandler<3> &
    dof_handler() const
    {
      return dof_handler_;
    }

    /// Partitioner shared by every state vector (owned + locally relevant DOFs).
    const std::shared_ptr<const dealii::Utilities::MPI::Partitioner> &
    partitioner() const
    {
      return partitioner_;
    }

    /// Reference positions X of every owned and ghost DOF (ghost values set).
    const Vector &
    reference_positions() const
    {
      return reference_;
    }

    /// A new vector with the shared layout, zero.
    void
    initialize_vector(Vector &v) const
    {
      v.reinit(partitioner_);
    }

    /**
     * @brief The key of local vertex @p local_vertex (an index of `triangulation().get_vertices()`):
     * its index in the merged mesh of all bodies, the same at any rank count and partition.
     */
    std::uint64_t
    vertex_key(const unsigned int local_vertex) const
    {
      return vertex_key_[local_vertex];
    }

    /// Number of vertices of the merged mesh of all bodies (keys are below it).
    std::uint64_t
    n_global_vertices() const
    {
      return n_global_vertices_;
    }

    /// Number of active cells in all bodies.
    dealii::types::global_cell_index
    n_elements() const
    {
      return triangulation_.n_global_active_cells();
    }

    /// Communicator of the run.
    MPI_Comm
    communicator() const
    {
      return comm_;
    }

    /**
     * @brief Local indices of the first DOF of each owned node on boundary @p boundary_id of
     * body @p body (all boundary nodes of the body when @p boundary_id is -1).
     */
    std::vector<unsigned int>
    boundary_nodes(unsigned int body, int boundary_id) const;

    /**
     * @brief Reference area assigned to each owned node of the faces with @p boundary_id of
     * @p body (a quarter of each face area per node). Returns (first local DOF, area) pairs.
     * @note Collective.
     */
    std::vector<std::pair<unsigned int, double>>
    boundary_node_areas(unsigned int body, int boundary_id) const;

    /// Local indices of the first DOF of each owned node of @p body.
    std::vector<unsigned int>
    body_nodes(unsigned int body) const;

    /// The boundary ids on the faces of @p body (the same on every rank; after prepare()).
    const std::set<unsigned int> &
    boundary_ids(const unsigned int body) const
    {
      return body_boundary_ids_.at(body);
    }

    /// "0, 1, 2" for the boundary ids of @p body, for messages.
    std::string
    boundary_ids_text(unsigned int body) const;

    /**
     * @brief Adds @p extra (global DOF indices, owned ones are ignored) to the ghost set and
     * rebuilds the partitioner and the reference positions. Local indices of ghosts change:
     * call it before any component stores local indices (ParticleSet does, for its two-hop
     * stencil).
     * @note Collective.
     */
    void
    add_ghost_dofs(const dealii::IndexSet &extra);

  private:
    /// DoFs, partitioner and reference positions of the current triangulation.
    void
    distribute();

    /// One cell as it travels between ranks: the whole coarse-cell description (.cc).
    struct CellRecord;

    /// Builds this rank's triangulation from the records of its own and ghost cells (any order,
    /// each cell once) and sets the vertex keys.
    void
    create_from(std::vector<CellRecord> &records);

    MPI_Comm                                                comm_;
    std::vector<std::string>                                body_names_ = {"body"};
    std::string                                             body_names_text_ = "body";
    double                                                  particle_weight_ = default_particle_weight;
    double                                                  imbalance_by_count_ = 0;
    int                                                     max_cells_       = 4000000;
    std::vector<std::set<unsigned int>>                     body_boundary_ids_;
    std::vector<BodyParameters>                             bodies_;
    std::map<std::string, std::unique_ptr<BodyParameters>> declared_;
    Triangulation                                           triangulation_;
    /// Merged-mesh index of each local vertex (vertex_key()).
    std::vector<std::uint64_t>                              vertex_key_;
    std::uint64_t                                           n_global_vertices_ = 0;
    dealii::FESystem<3>                                     fe_;
    dealii::DoFHandler<3>                                   dof_handler_;
    std::shared_ptr<const dealii::Utilities::MPI::Partitioner> partitioner_;
    Vector                                                  reference_;
  };
} // namespace shard::mesh
