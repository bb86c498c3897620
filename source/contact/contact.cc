// SPDX-License-Identifier: LGPL-2.1-or-later
#include <shard/base/binary_archive.h>
#include <shard/base/region_boxes.h>
#include <shard/base/sections.h>
#include <shard/base/traffic.h>
#include <shard/contact/contact.h>
#include <shard/contact/node_to_surface.h>
#include <shard/contact/particle_pairs.h>
#include <shard/contact/rigid_wall.h>

#include <deal.II/base/mpi.h>

#include <algorithm>
#include <cmath>
#include <iterator>
#include <limits>
#include <sstream>

namespace shard::contact
{
  using namespace dealii;

  namespace
  {
    /// Doubles per node in the set-up table.
    constexpr unsigned int node_record = 13;
    /// Doubles per node in the step exchange: x and v.
    constexpr unsigned int state_record = ContactNodes::state_record;

    /// x y rounded on its own, not fused with the sum it is added to (a fused multiply-add is
    /// the compiler's choice and changed with the layout of the operands): the dissipated
    /// energies keep the rounding they had before the contact split.
    double
    rounded_product(const double x, const double y)
    {
      volatile double p = x * y;
      return p;
    }

    double
    norm(const Vec3 &a)
    {
      return std::sqrt(a[0] * a[0] + a[1] * a[1] + a[2] * a[2]);
    }
  } // namespace

  bool
  Contact::declare_parameters(ParameterHandler &prm)
  {
    bool added = false;
    prm.enter_subsection(sections::contact);
    if (!declared_)
      {
        declared_ = added = true;
        prm.add_parameter("interactions", names_text_,
                          "Comma-separated names of contact interactions; each has a subsection. Empty: no "
                          "contact.");
        prm.add_parameter("skin", skin_,
                          "Search margin: candidate pairs are found within contact distance + skin and rebuilt "
                          "when a node has moved more than skin/2 since the last build (a fast node gets the "
                          "distance it covers in 16 steps instead). 0: the smallest contact spacing. Unit: m. "
                          "Range: >= 0.",
                          Patterns::Double(0));
        prm.add_parameter("rebuild interval", rebuild_interval_,
                          "Steps after which the candidate pairs are rebuilt even if no node moved skin/2. Unit: "
                          "steps. Range: >= 1.",
                          Patterns::Integer(1));
        prm.add_parameter("friction velocity", friction_velocity_,
                          "Sliding speed below which the Coulomb friction force grows linearly with the speed "
                          "(regularization). Unit: m/s. Range: > 0.",
                          Patterns::Double(0));
      }
    names_ = base::split(names_text_, ',');
    for (const auto &name : names_)
      {
        if (declared_names_.count(name))
          continue;
        declared_names_.insert(name);
        added   = true;
        auto &s = settings_[name];
        prm.enter_subsection(name);
        prm.add_parameter("type", s.type_text,
                          "node to surface: nodes (FE surface nodes, all particles) of 'body' against the "
                          "surface faces of the FE body 'target'; particles: particle against particle among "
                          "the particles of 'body' (debris, pairs without an intact bond); rigid wall: nodes of "
                          "'body' against a plane.",
                          Patterns::Selection("node to surface|particles|rigid wall"));
        prm.add_parameter("body", s.body_text, "Body names (comma separated) whose nodes or particles take part.");
        prm.add_parameter("target", s.target, "node to surface: the FE body whose surface faces are the segments.");
        prm.add_parameter("symmetric", s.symmetric,
                          "node to surface: also the surface nodes of 'target' against the faces of 'body' "
                          "(both FE), so neither surface passes through the other.");
        prm.add_parameter("penalty scale", s.penalty,
                          "Penalty stiffness factor s: k = s K A^2 / V per segment (K bulk modulus, A face "
                          "area, V element volume), k = s K h per node for particles and walls (h spacing). "
                          "LS-DYNA's SLSFAC default is 0.1. The step shrinks when 2 sqrt(m/k) falls below the "
                          "element step. Unit: 1. Range: > 0.",
                          Patterns::Double(0));
        prm.add_parameter("friction coefficient", s.friction,
                          "Coulomb friction coefficient mu (regularized below 'friction velocity'). Unit: 1. "
                          "Range: >= 0.",
                          Patterns::Double(0));
        prm.add_parameter("damping ratio", s.damping,
                          "Normal damping of each contact spring, a fraction zeta of its critical damping: the "
                          "normal force is max(0, k g - c v_n) with c = 2 zeta sqrt(k m*), m* the reduced mass of "
                          "the pair (the node's mass against a wall), v_n the normal approach speed; it never "
                          "pulls. A head-on collision of two masses then rebounds with a restitution coefficient "
                          "below 1 (0.53 without the clipping at zeta = 0.2), as colliding debris does; the energy "
                          "it takes is history column contact_damping_energy. 0: elastic contact. Unit: 1. "
                          "Range: 0 to below 1.",
                          Patterns::Double(0, 1));
        prm.add_parameter("wall point", s.wall_point, "rigid wall: a point of the plane. Unit: m.");
        prm.add_parameter("wall normal", s.wall_normal, "rigid wall: normal of the plane, towards the body. Unit: 1.");
        prm.leave_subsection();
      }
    prm.leave_subsection();
    return added;
  }

  void
  Contact::check_parameters(const base::PrmSource &source) const
  {
    const std::string top = sections::contact + "/";
    base::check_names(source, top + "interactions", names_text_, names_, true);
    if (!names_.empty() && !(friction_velocity_ > 0))
      source.fail(top + "friction velocity", std::to_string(friction_velocity_), "> 0. Unit: m/s.");
    for (const auto &name : names_)
      {
        const auto &s = settings_.at(name);
        if (!(s.penalty > 0))
          source.fail(top + name + "/penalty scale", std::to_string(s.penalty), "> 0.");
        if (!(s.damping >= 0 && s.damping < 1))
          source.fail(top + name + "/damping ratio", std::to_string(s.damping), "0 to below 1.");
        if (s.type_text == "rigid wall")
          for (const auto &[key, text] : {std::make_pair("wall point", s.wall_point),
                                          std::make_pair("wall normal", s.wall_normal)})
            {
              try
                {
                  const Vec3 p = base::parse_point(text);
                  if (std::string(key) == "wall normal" && !(norm(p) > 0))
                    source.fail(top + name + "/" + key, text, "a nonzero vector.");
                }
              catch (const std::invalid_argument &e)
                {
                  source.fail(top + name + "/" + key, text, std::string(e.what()) + ".");
                }
            }
      }
  }

  std::unique_ptr<Interaction>
  make_interaction(const InteractionSettings &settings)
  {
    if (settings.type_text == "particles")
      return std::make_unique<ParticlePairs>(settings);
    if (settings.type_text == "rigid wall")
      return std::make_unique<RigidWall>(settings);
    return std::make_unique<NodeToSurface>(settings);
  }

  std::vector<InteractionSettings>
  Contact::resolve(const mesh::Discretization &discretization, const materials::MaterialLibrary &materials,
                   const particles::ParticleSet &particles, const base::PrmSource &source) const
  {
    const auto &bodies     = discretization.bodies();
    const auto  body_index = [&](const std::string &name, const std::string &key) {
      for (unsigned int b = 0; b < bodies.size(); ++b)
        if (bodies[b].name == name)
          return b;
      source.fail(key, name, "a body of 'B - Mesh/body names'.");
    };
    std::vector<InteractionSettings> resolved;
    for (const auto &name : names_)
      {
        InteractionSettings s = settings_.at(name);
        s.name                = name;
        const std::string key = sections::contact + "/" + name + "/";
        if (base::split(s.body_text, ',').empty())
          source.fail(key + "body", s.body_text, "at least one body name of 'B - Mesh/body names'.");
        if (s.type_text == "node to surface" && s.target.empty())
          source.fail(key + "target", s.target, "the name of an FE body.");
        for (const auto &b : base::split(s.body_text, ','))
          s.bodies.push_back(body_index(b, key + "body"));
        if (s.type_text == "node to surface")
          {
            s.target_body = body_index(s.target, key + "target");
            if (particles.is_particle_body(s.target_body))
              source.fail(key + "target", s.target, "an FE body (particle bodies meet through type 'particles').");
            s.rigid_target = materials.get(bodies[s.target_body].material).rigid();
          }
        if (s.type_text == "rigid wall")
          {
            s.point  = base::parse_point(s.wall_point);
            s.normal = base::parse_point(s.wall_normal);
            const double l = norm(s.normal);
            for (auto &c : s.normal)
              c /= l;
          }
        resolved.push_back(s);
      }
    return resolved;
  }

  void
  Contact::prepare(const mesh::Discretization &discretization, const materials::MaterialLibrary &materials,
                   const particles::ParticleSet &particles, const std::vector<bool> &converted_cells,
                   const mesh::Vector &mass, const base::PrmSource &source)
  {
    comm_      = discretization.communicator();
    particles_ = &particles;
    // A second call (after a conversion) keeps the state of the contacts that go on.
    const Carried carried = carry();
    const auto    before  = std::move(interactions_);
    interactions_.clear();
    std::vector<bool> involved(discretization.bodies().size(), false);
    const bool        speaks = Utilities::MPI::this_mpi_process(comm_) == 0;
    const MPI_Comm    comm   = comm_;
    for (const auto &s : resolve(discretization, materials, particles, source))
      {
        for (const unsigned int b : s.bodies)
          involved[b] = true;
        if (s.type_text == "node to surface")
          involved[s.target_body] = true;
        interactions_.push_back(make_interaction(s));
        interactions_.back()->set_print_notices(speaks);
        interactions_.back()->set_global_max([comm](const double x) { return Utilities::MPI::max(x, comm); });
        if (before.size() > interactions_.size() - 1)
          interactions_.back()->keep_notices(*before[interactions_.size() - 1]);
      }
    if (interactions_.empty())
      return;

    gather(discretization, materials, particles, converted_cells, mass, involved);
    nodes_ = ContactNodes();
    own_index_.clear();
    send_ranks_.clear(), recv_ranks_.clear(), send_lists_.clear(), recv_lists_.clear();
    force_.clear();
    own_force_.assign(3 * own_.size(), 0.);
    own_force_old_.assign(3 * own_.size(), 0.);
    own_state_.assign(state_record * own_.size(), 0.);
    x_old_.clear();
    for (auto &in : interactions_)
      in->reset(nodes_);
    bonds_.reset(nodes_);
    built_         = false;
    halo_stale_    = true;
    build_pending_ = false;
    stable_stale_  = true;
    pending_       = Pending();

    // Skin: the smallest contact spacing of any rank.
    double smallest = 1e300;
    for (const auto &n : own_)
      smallest = std::min(smallest, n.spacing);
    smallest   = Utilities::MPI::min(smallest, comm_);
    skin_used_ = skin_ > 0 ? skin_ : smallest;
    restore(carried);
  }

  namespace
  {
    /// The static record of a node (node_record doubles; the set-up table of gather() and the
    /// halo's messages).
    void
    pack_node(const ContactNode &n, std::vector<double> &out)
    {
      out.insert(out.end(), {double(n.dof), n.X[0], n.X[1], n.X[2], n.mass, n.radius, n.bulk, n.spacing,
                             double(n.body), n.particle ? 1. : 0., n.support[0], n.support[1], n.support[2]});
    }

    /// The node of a record (not owned).
    ContactNode
    unpack_node(const double *a)
    {
      ContactNode n;
      n.dof      = static_cast<unsigned long long>(a[0]);
      n.X        = Vec3{{a[1], a[2], a[3]}};
      n.mass     = a[4];
      n.radius   = a[5];
      n.bulk     = a[6];
      n.spacing  = a[7];
      n.body     = static_cast<unsigned int>(a[8]);
      n.particle = a[9] > 0;
      n.support  = Vec3{{a[10], a[11], a[12]}};
      n.owned    = false;
      return n;
    }

    /// Distance from @p x to the box [lo, hi] (0 inside).
    double
    box_distance(const Vec3 &x, const double *lo, const double *hi)
    {
      double d2 = 0;
      for (unsigned int c = 0; c < 3; ++c)
        {
          const double e = std::max({lo[c] - x[c], 0., x[c] - hi[c]});
          d2 += e * e;
        }
      return std::sqrt(d2);
    }

    /// Distance between the boxes [alo, ahi] and [blo, bhi] (0 where they overlap).
    double
    box_box_distance(const Vec3 &alo, const Vec3 &ahi, const double *blo, const double *bhi)
    {
      double d2 = 0;
      for (unsigned int c = 0; c < 3; ++c)
        {
          const double e = std::max({blo[c] - ahi[c], 0., alo[c] - bhi[c]});
          d2 += e * e;
        }
      return std::sqrt(d2);
    }
  } // namespace

  void
  Contact::gather(const mesh::Discretization &discretization, const materials::MaterialLibrary &materials,
                  const particles::ParticleSet &particles, const std::vector<bool> &converted_cells,
                  const mesh::Vector &mass, const std::vector<bool> &involved)
  {
    const auto &bodies = discretization.bodies();
    const auto &pt     = *discretization.partitioner();
    const auto &X      = discretization.reference_positions();
    reference_         = &X;
    std::map<unsigned long long, std::array<double, node_record>> mine; // by global DOF
    const auto bulk_of = [&](const unsigned int b) { return materials.get(bodies[b].material).elastic_moduli()[0]; };
    const auto add_node = [&](const types::global_dof_index g, const unsigned int b, const double h,
                              const bool is_particle, const Vec3 &support) {
      const unsigned int j  = pt.global_to_local(g);
      auto               it = mine.find(g);
      if (it == mine.end())
        {
          std::array<double, node_record> r{};
          r[0] = double(g);
          for (unsigned int c = 0; c < 3; ++c)
            r[1 + c] = X.local_element(j + c);
          r[4] = mass.local_element(j);
          r[5] = is_particle ? 0.5 * h : 0.;
          r[6] = bulk_of(b);
          r[7] = h;
          r[8] = b;
          r[9] = is_particle;
          for (unsigned int c = 0; c < 3; ++c)
            r[10 + c] = support[c];
          it = mine.emplace(g, r).first;
        }
      it->second[7] = std::max(it->second[7], h);
    };
    for (unsigned int i = 0; i < particles.n_owned(); ++i)
      if (involved[particles.body(i)])
        {
          const auto &h       = particles.spacing(i);
          const Vec3  support = particles.support_radius(i);
          add_node(pt.local_to_global(particles.local_dof(i)), particles.body(i), std::min({h[0], h[1], h[2]}), true,
                   support);
        }
    // The owner of a ghost DOF, from the partitioner's ghost ranges.
    std::vector<std::pair<unsigned int, unsigned int>> ghost_ranges; // (first ghost number past the range, rank)
    {
      unsigned int end = 0;
      for (const auto &[r, count] : pt.ghost_targets())
        ghost_ranges.emplace_back(end += count, r);
    }
    const auto owner_of = [&](const unsigned int local) {
      const unsigned int t  = local - pt.locally_owned_size();
      const auto         it = std::upper_bound(ghost_ranges.begin(), ghost_ranges.end(), std::make_pair(t, ~0u));
      return it->second;
    };
    // The faces: this rank's segments; a face node owned elsewhere is told to its owner, which
    // makes it a contact node (a node may be owned by a rank that owns no face with it).
    own_segments_.clear();
    std::map<unsigned int, std::vector<double>> notices; // per rank: DOF, body, spacing
    for (const auto &cell : discretization.dof_handler().active_cell_iterators())
      {
        if (!cell->is_locally_owned() || converted_cells[cell->active_cell_index()] ||
            !involved[cell->material_id()])
          continue;
        const unsigned int b      = cell->material_id();
        const double       volume = cell->measure();
        const double       h      = std::cbrt(volume);
        Point<3>           centre = cell->center();
        for (const unsigned int f : cell->face_indices())
          {
            const bool surface = cell->face(f)->at_boundary() || converted_cells[cell->neighbor(f)->active_cell_index()];
            if (!surface)
              continue;
            const auto face = cell->face(f);
            // Counter-clockwise seen from outside: lexicographic 0 1 3 2, reversed if the
            // normal points into the cell.
            std::array<unsigned int, 4> order{{0, 1, 3, 2}};
            const Point<3>     x0 = face->vertex(0), x1 = face->vertex(1), x3 = face->vertex(3);
            const Tensor<1, 3> n = cross_product_3d(x1 - x0, x3 - x0);
            if (n * (face->center() - centre) < 0)
              std::swap(order[1], order[3]);
            const double area = face->measure();
            OwnSegment   seg;
            for (unsigned int v = 0; v < 4; ++v)
              {
                const auto g = face->vertex_dof_index(order[v], 0);
                seg.dof[v]   = g;
                seg.local[v] = pt.global_to_local(g);
                seg.owner[v] = pt.in_local_range(g) ? Utilities::MPI::this_mpi_process(comm_) : owner_of(seg.local[v]);
                if (pt.in_local_range(g))
                  add_node(g, b, h, false, Vec3{{0, 0, 0}});
                else
                  {
                    auto &to = notices[owner_of(seg.local[v])];
                    to.insert(to.end(), {double(g), double(b), h});
                  }
              }
            seg.stiffness = area * area / volume * bulk_of(b);
            seg.body      = b;
            own_segments_.push_back(seg);
          }
      }
    // Particle bodies' nodes on intact cells are FE nodes; those of converted cells were added
    // as particles above.
    if (Utilities::MPI::n_mpi_processes(comm_) > 1)
      for (const auto &[from, list] : Utilities::MPI::some_to_some(comm_, notices))
        for (std::size_t p = 0; p < list.size(); p += 3)
          add_node(static_cast<types::global_dof_index>(list[p]), static_cast<unsigned int>(list[p + 1]), list[p + 2],
                   false, Vec3{{0, 0, 0}});
    own_.clear();
    owned_local_dof_.clear();
    for (const auto &[g, r] : mine)
      {
        own_.push_back(unpack_node(r.data()));
        own_.back().owned = true;
        owned_local_dof_.push_back(pt.global_to_local(g));
      }
  }


  void
  Contact::copy_own_states()
  {
    for (std::size_t k = 0; k < own_index_.size(); ++k)
      std::copy_n(&own_state_[state_record * k], state_record, &nodes_.state[state_record * own_index_[k]]);
  }

  double
  Contact::build_halo(const double dt)
  {
    HaloParts    parts = exchange_halo(dt);
    const double bytes = parts.bytes;
    install_halo(std::move(parts));
    return bytes;
  }

  Contact::HaloParts
  Contact::exchange_halo(const double dt)
  {
    const unsigned int rank = Utilities::MPI::this_mpi_process(comm_);
    const unsigned int P    = Utilities::MPI::n_mpi_processes(comm_);
    const std::size_t  n_own = own_.size();
    // The margins: a node of another rank is in the halo when it can meet one of this rank's
    // nodes before the next build. Reach (the fastest node of any rank, as build_candidates()
    // computes it), contact radius, face depth and the deepest followed penetration, and the
    // size of a segment at its present positions.
    const double base = 0.5 * skin_used_;
    std::array<double, 5> m{{base, 0., 0., 0., 0.}}; // reach, radius, spacing, depth, segment size
    for (std::size_t k = 0; k < n_own; ++k)
      {
        const double *v = &own_state_[state_record * k + 3];
        m[0]            = std::max(m[0], reach_steps * dt * std::sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2]));
        m[1]            = std::max(m[1], own_[k].radius);
        m[2]            = std::max(m[2], own_[k].spacing);
      }
    for (const auto &in : interactions_)
      m[3] = std::max(m[3], in->search_depth());
    // Current positions of the own segments' nodes (d has its ghost values).
    std::vector<std::array<Vec3, 2>> segment_box(own_segments_.size());
    for (std::size_t s = 0; s < own_segments_.size(); ++s)
      {
        const auto &seg = own_segments_[s];
        Vec3        lo{{1e300, 1e300, 1e300}}, hi{{-1e300, -1e300, -1e300}};
        for (unsigned int v = 0; v < 4; ++v)
          for (unsigned int c = 0; c < 3; ++c)
            {
              const double x = reference_->local_element(seg.local[v] + c) + d_->local_element(seg.local[v] + c);
              lo[c]          = std::min(lo[c], x);
              hi[c]          = std::max(hi[c], x);
            }
        segment_box[s] = {{lo, hi}};
        m[4]           = std::max(m[4], std::sqrt((hi[0] - lo[0]) * (hi[0] - lo[0]) + (hi[1] - lo[1]) * (hi[1] - lo[1]) +
                                                  (hi[2] - lo[2]) * (hi[2] - lo[2])));
      }
    if (P > 1)
      Utilities::MPI::max(ArrayView<const double>(m.data(), m.size()), comm_, ArrayView<double>(m.data(), m.size()));
    // Node to surface: a slave meets a segment within the face depth + penetration + both
    // reaches of the segment's box (its nodes come with it); particles: within both radii and
    // both reaches. 1 % and an absolute floor against round-off.
    const double reach           = m[0];
    const double segment_margin  = 1.01 * (m[2] + m[3] + 2. * reach) + 1e-12;
    const double particle_margin = 1.01 * (2. * m[1] + 2. * reach) + 1e-12;

    // This rank's region: the tight boxes of its nodes in the cells of a grid (edge twice the
    // node margin, or an eighth of the extent of its nodes if larger: at most 512 boxes). One
    // box around all of them would hold most of another rank's nodes wherever the partition is
    // not compact (a rank with cells at both ends of the block).
    std::vector<Vec3> own_x(n_own);
    for (std::size_t k = 0; k < n_own; ++k)
      own_x[k] = Vec3{{own_state_[state_record * k], own_state_[state_record * k + 1], own_state_[state_record * k + 2]}};
    const std::vector<double> boxes_mine =
      base::RegionBoxes(own_x, 2. * std::max(segment_margin, particle_margin)).boxes; // 6 per box: lo, hi
    const auto boxes = P > 1 ? Utilities::MPI::all_gather(comm_, boxes_mine) : std::vector<std::vector<double>>{boxes_mine};

    // Round 1: own segments near one of a rank's boxes go to it (node DOFs, stiffness, body;
    // this rank included), and the owners of their nodes are asked to send those nodes there.
    BinGrid node_grid, segment_grid;
    if (n_own > 0)
      node_grid.build(own_x, particle_margin);
    std::vector<Vec3> segment_centre(own_segments_.size());
    for (std::size_t s = 0; s < own_segments_.size(); ++s)
      for (unsigned int c = 0; c < 3; ++c)
        segment_centre[s][c] = 0.5 * (segment_box[s][0][c] + segment_box[s][1][c]);
    if (!own_segments_.empty())
      segment_grid.build(segment_centre, segment_margin + m[4]);
    std::vector<std::vector<double>>                        segments_to(P);
    std::vector<std::vector<std::pair<unsigned long long, unsigned int>>> requests_to(P); // (DOF, for rank)
    std::vector<unsigned int> segment_stamp(own_segments_.size(), ~0u);
    for (unsigned int r = 0; r < P; ++r)
      for (std::size_t b = 0; b + 6 <= boxes[r].size() && !own_segments_.empty(); b += 6)
        {
          const double *lo = &boxes[r][b], *hi = &boxes[r][b + 3];
          const double  grow = segment_margin + 0.5 * m[4] * 1.01;
          segment_grid.for_each_in_box(
            Vec3{{lo[0] - grow, lo[1] - grow, lo[2] - grow}}, Vec3{{hi[0] + grow, hi[1] + grow, hi[2] + grow}},
            [&](const unsigned int g) {
              if (segment_stamp[g] == r ||
                  box_box_distance(segment_box[g][0], segment_box[g][1], lo, hi) > segment_margin)
                return;
              segment_stamp[g] = r;
              const auto &seg  = own_segments_[g];
              segments_to[r].insert(segments_to[r].end(), {double(seg.dof[0]), double(seg.dof[1]), double(seg.dof[2]),
                                                           double(seg.dof[3]), seg.stiffness, double(seg.body)});
              for (unsigned int v = 0; v < 4; ++v)
                if (seg.owner[v] != r)
                  requests_to[seg.owner[v]].emplace_back(seg.dof[v], r);
            });
        }
    double bytes = 0;
    std::map<unsigned int, std::vector<double>> out;
    for (unsigned int r = 0; r < P; ++r)
      if (r != rank && (!segments_to[r].empty() || !requests_to[r].empty()))
        {
          auto &o = out[r];
          o.push_back(double(segments_to[r].size() / 6));
          o.insert(o.end(), segments_to[r].begin(), segments_to[r].end());
          for (const auto &[g, to] : requests_to[r])
            o.insert(o.end(), {double(g), double(to)});
          bytes += sizeof(double) * o.size();
        }
    const auto first = P > 1 ? Utilities::MPI::some_to_some(comm_, out) : std::map<unsigned int, std::vector<double>>();

    // Round 2: own nodes to each rank: those asked for (segment nodes) and the particles near
    // one of its boxes (partners of particle pairs).
    std::vector<std::vector<unsigned int>> sent(P);
    std::vector<unsigned int>              node_stamp(n_own, ~0u);
    const auto                             k_of = [&](const unsigned long long dof) {
      const auto it = std::lower_bound(own_.begin(), own_.end(), dof,
                                       [](const ContactNode &n, const unsigned long long g) { return n.dof < g; });
      if (it == own_.end() || it->dof != dof)
        throw std::logic_error("contact halo: a segment node is not a contact node of its owner");
      return static_cast<unsigned int>(it - own_.begin());
    };
    std::vector<std::vector<unsigned int>> asked(P);
    for (const auto &[g, to] : requests_to[rank])
      asked[to].push_back(k_of(g));
    for (const auto &[from, list] : first)
      {
        std::size_t p = 1 + 6 * static_cast<std::size_t>(list[0]);
        for (; p + 2 <= list.size(); p += 2)
          asked[static_cast<unsigned int>(list[p + 1])].push_back(k_of(static_cast<unsigned long long>(list[p])));
      }
    for (unsigned int r = 0; r < P; ++r)
      {
        if (r == rank)
          continue;
        for (const unsigned int k : asked[r])
          if (node_stamp[k] != r)
            {
              node_stamp[k] = r;
              sent[r].push_back(k);
            }
        for (std::size_t b = 0; b + 6 <= boxes[r].size() && n_own > 0; b += 6)
          {
            const double *lo = &boxes[r][b], *hi = &boxes[r][b + 3];
            node_grid.for_each_in_box(
              Vec3{{lo[0] - particle_margin, lo[1] - particle_margin, lo[2] - particle_margin}},
              Vec3{{hi[0] + particle_margin, hi[1] + particle_margin, hi[2] + particle_margin}},
              [&](const unsigned int k) {
                if (node_stamp[k] != r && own_[k].particle && box_distance(own_x[k], lo, hi) <= particle_margin)
                  {
                    node_stamp[k] = r;
                    sent[r].push_back(k);
                  }
              });
          }
        // In own order (the receiver's positions are the order of arrival).
        std::sort(sent[r].begin(), sent[r].end());
      }
    out.clear();
    for (unsigned int r = 0; r < P; ++r)
      if (r != rank && !sent[r].empty())
        {
          auto &o = out[r];
          for (const unsigned int k : sent[r])
            {
              pack_node(own_[k], o);
              o.insert(o.end(), &own_state_[state_record * k], &own_state_[state_record * k] + state_record);
            }
          bytes += sizeof(double) * o.size();
        }
    HaloParts parts;
    if (P > 1)
      parts.nodes = Utilities::MPI::some_to_some(comm_, out);
    // Boxes: 48 B each to every other rank.
    bytes += base::Traffic::to_all_others(sizeof(double) * boxes_mine.size(), comm_);
    const auto take_segments = [&](const std::vector<double> &list, std::size_t p, const std::size_t end) {
      for (; p + 6 <= end; p += 6)
        {
          std::array<double, 6> r;
          std::copy_n(&list[p], 6, r.begin());
          parts.segments.push_back(r);
        }
    };
    take_segments(segments_to[rank], 0, segments_to[rank].size());
    for (const auto &[from, list] : first)
      take_segments(list, 1, 1 + 6 * static_cast<std::size_t>(list[0]));
    parts.sent  = std::move(sent);
    parts.bytes = bytes;
    return parts;
  }

  void
  Contact::install_halo(HaloParts &&parts)
  {
    const unsigned int rank  = Utilities::MPI::this_mpi_process(comm_);
    const unsigned int P     = Utilities::MPI::n_mpi_processes(comm_);
    const std::size_t  n_own = own_.size();
    const auto        &sent  = parts.sent;

    // The new node list: own and received nodes, sorted by DOF; segments sorted by their DOFs.
    struct Entry
    {
      ContactNode  node;
      const double *state;
      unsigned int from, position; // rank and place in its message (own: rank, k)
    };
    std::vector<Entry> entries;
    for (std::size_t k = 0; k < n_own; ++k)
      entries.push_back({own_[k], &own_state_[state_record * k], rank, static_cast<unsigned int>(k)});
    for (const auto &[from, list] : parts.nodes)
      for (std::size_t p = 0, t = 0; p + node_record + state_record <= list.size(); p += node_record + state_record, ++t)
        entries.push_back({unpack_node(&list[p]), &list[p + node_record], from, static_cast<unsigned int>(t)});
    std::sort(entries.begin(), entries.end(), [](const Entry &a, const Entry &b) { return a.node.dof < b.node.dof; });

    ContactNodes next;
    next.nodes.reserve(entries.size());
    next.state.resize(state_record * entries.size());
    std::vector<unsigned int> own_index(n_own);
    std::map<unsigned int, std::vector<std::pair<unsigned int, unsigned int>>> from_rank; // rank: (position, index)
    std::unordered_map<unsigned long long, unsigned int>                       index_of;
    for (unsigned int i = 0; i < entries.size(); ++i)
      {
        const auto &e = entries[i];
        next.nodes.push_back(e.node);
        std::copy_n(e.state, state_record, &next.state[state_record * i]);
        index_of.emplace(e.node.dof, i);
        if (e.node.owned)
          own_index[e.position] = i;
        else
          from_rank[e.from].emplace_back(e.position, i);
      }
    // Segments (a segment has one owner, the owner of its cell): sorted by their node DOFs.
    for (const auto &r : parts.segments)
      {
        ContactSegment g;
        for (unsigned int v = 0; v < 4; ++v)
          {
            const auto it = index_of.find(static_cast<unsigned long long>(r[v]));
            if (it == index_of.end())
              throw std::logic_error("contact halo: a node of a segment did not arrive (margin)");
            g.node[v] = it->second;
          }
        g.stiffness = r[4];
        g.body      = static_cast<unsigned int>(r[5]);
        next.segments.push_back(g);
      }
    {
      std::vector<std::pair<std::array<unsigned long long, 4>, unsigned int>> order;
      for (unsigned int g = 0; g < next.segments.size(); ++g)
        order.emplace_back(next.segment_dofs(g), g);
      std::sort(order.begin(), order.end());
      std::vector<ContactSegment> sorted;
      for (const auto &o : order)
        sorted.push_back(next.segments[o.second]);
      next.segments.swap(sorted);
    }

    // Exchange lists of the following steps.
    send_ranks_.clear(), send_lists_.clear(), recv_ranks_.clear(), recv_lists_.clear();
    for (unsigned int r = 0; r < P; ++r)
      if (r != rank && !sent[r].empty())
        {
          send_ranks_.push_back(r);
          send_lists_.push_back(sent[r]);
        }
    for (auto &[r, list] : from_rank)
      {
        std::sort(list.begin(), list.end());
        recv_ranks_.push_back(r);
        recv_lists_.emplace_back();
        for (const auto &pi : list)
          recv_lists_.back().push_back(pi.second);
      }

    // The interactions' per-node state follows the nodes (only when the list changed: on one
    // rank it never does).
    bool same = next.nodes.size() == nodes_.nodes.size() && next.segments.size() == nodes_.segments.size();
    for (std::size_t i = 0; same && i < next.nodes.size(); ++i)
      same = next.nodes[i].dof == nodes_.nodes[i].dof;
    for (std::size_t g = 0; same && g < next.segments.size(); ++g)
      same = next.segments[g].node == nodes_.segments[g].node;
    if (same)
      {
        nodes_.state.swap(next.state);
      }
    else
      {
        // Written by DOF and read into the new list like a conversion's states. (pending_ is
        // empty here: it is set only after prepare() emptied the node list.)
        if (!nodes_.nodes.empty())
          pending_ = written_states();
        nodes_ = std::move(next);
        for (auto &in : interactions_)
          in->reset(nodes_);
        bonds_.reset(nodes_);
        bonds_.sync(particles_->broken_bonds(), particles_->free_particles());
        read_pending();
      }
    own_index_ = std::move(own_index);
    force_.assign(3 * nodes_.size(), 0.);
    halo_stale_ = false;
    if (stable_stale_)
      {
        stable_dt_ = 1e300;
        for (const auto &in : interactions_)
          stable_dt_ = std::min(stable_dt_, in->stable_dt(nodes_));
        stable_dt_    = Utilities::MPI::min(stable_dt_, comm_);
        stable_stale_ = false;
      }
  }

  void
  Contact::read_pending()
  {
    if (pending_.dofs.empty())
      return;
    std::unordered_map<unsigned long long, unsigned int> index_of;
    for (unsigned int i = 0; i < nodes_.size(); ++i)
      index_of.emplace(nodes_.nodes[i].dof, i);
    NodeNaming naming;
    naming.index = [&](const unsigned long long name) {
      const auto it = index_of.find(pending_.dof_of_name(name));
      return it == index_of.end() ? -1 : static_cast<int>(it->second);
    };
    for (std::size_t q = 0; q < pending_.dofs.size(); ++q)
      {
        if (pending_.interactions[q].size() != interactions_.size())
          continue;
        // A writer's state counts for the nodes it owned and this rank owns (each rank
        // evaluates the pairs of its own nodes).
        std::vector<int> where(pending_.dofs[q].size(), -1);
        for (std::size_t k = 0; k < where.size(); ++k)
          if (pending_.owned[q][k])
            {
              const auto it = index_of.find(pending_.dofs[q][k]);
              if (it != index_of.end() && nodes_.nodes[it->second].owned)
                where[k] = static_cast<int>(it->second);
            }
        for (std::size_t s = 0; s < interactions_.size(); ++s)
          {
            base::BinaryReader in(pending_.interactions[q][s]);
            interactions_[s]->read_state(in, nodes_, where, naming);
          }
      }
    pending_ = Pending();
  }

  Contact::Pending
  Contact::written_states() const
  {
    Pending p;
    p.dofs.emplace_back();
    p.owned.emplace_back();
    for (const auto &n : nodes_.nodes)
      {
        p.dofs.back().push_back(n.dof);
        p.owned.back().push_back(n.owned);
      }
    NodeNaming naming;
    naming.name = [&](const unsigned int i) { return nodes_.nodes[i].dof; };
    p.interactions.emplace_back();
    for (const auto &in : interactions_)
      {
        base::BinaryWriter w;
        in->write_state(w, nodes_, naming);
        p.interactions.back().push_back(w.str());
      }
    p.dof_of_name = [](const unsigned long long dof) { return dof; };
    return p;
  }

  Contact::Carried
  Contact::carry() const
  {
    Carried c;
    if (interactions_.empty())
      return c;
    c.states = written_states();
    for (std::size_t k = 0; k < own_.size() && 3 * k < x_old_.size(); ++k)
      {
        c.owned_dof.push_back(own_[k].dof);
        c.force.insert(c.force.end(), &own_force_[3 * k], &own_force_[3 * k] + 3);
        c.x_old.insert(c.x_old.end(), &x_old_[3 * k], &x_old_[3 * k] + 3);
      }
    return c;
  }

  void
  Contact::restore(const Carried &c)
  {
    if (c.states.interactions.empty() || c.states.interactions.front().size() != interactions_.size())
      return;
    if (!c.states.dofs.front().empty())
      pending_ = c.states;
    // Forces and positions of the last step of this rank's nodes; a node new to the contact
    // has none (NaN: no work booked for it in the next step, when its force is still 0 from its
    // entry offset).
    std::unordered_map<unsigned long long, std::size_t> k_of;
    for (std::size_t k = 0; k < c.owned_dof.size(); ++k)
      k_of.emplace(c.owned_dof[k], k);
    if (!c.owned_dof.empty() || !own_.empty())
      {
        x_old_.assign(3 * own_.size(), std::numeric_limits<double>::quiet_NaN());
        for (std::size_t k = 0; k < own_.size(); ++k)
          {
            const auto it = k_of.find(own_[k].dof);
            if (it != k_of.end())
              {
                std::copy_n(&c.x_old[3 * it->second], 3, &x_old_[3 * k]);
                std::copy_n(&c.force[3 * it->second], 3, &own_force_[3 * k]);
              }
          }
      }
  }

  double
  Contact::memory_consumption() const
  {
    std::size_t lists = 0;
    for (const auto &l : send_lists_)
      lists += l.capacity();
    for (const auto &l : recv_lists_)
      lists += l.capacity();
    return sizeof(ContactNode) * (nodes_.nodes.capacity() + own_.capacity()) +
           sizeof(ContactSegment) * nodes_.segments.capacity() + sizeof(OwnSegment) * own_segments_.capacity() +
           sizeof(double) * (nodes_.state.capacity() + force_.capacity() + own_force_.capacity() +
                             own_force_old_.capacity() + x_old_.capacity() + reach_.capacity() +
                             own_state_.capacity()) +
           sizeof(Vec3) * x_build_.capacity() +
           sizeof(unsigned int) * (owned_local_dof_.capacity() + own_index_.capacity() + lists);
  }

  double
  Contact::exchange(const unsigned int step, const double dt, const mesh::Vector &d, const mesh::Vector &v)
  {
    if (interactions_.empty())
      return 0.;
    for (std::size_t k = 0; k < own_.size(); ++k)
      for (unsigned int c = 0; c < 3; ++c)
        {
          own_state_[state_record * k + c]     = own_[k].X[c] + d.local_element(owned_local_dof_[k] + c);
          own_state_[state_record * k + 3 + c] = v.local_element(owned_local_dof_[k] + c);
        }
    // Rebuild rule, one verdict for all ranks: the rebuild interval, or an own node moved more
    // than its reach since the last build.
    bool rebuild = halo_stale_ || !built_ || step >= last_build_ + rebuild_interval_;
    for (std::size_t k = 0; k < own_.size() && !rebuild; ++k)
      {
        const unsigned int i  = own_index_[k];
        const double      *x  = &own_state_[state_record * k];
        const Vec3         dx{{x[0] - x_build_[i][0], x[1] - x_build_[i][1], x[2] - x_build_[i][2]}};
        rebuild               = norm(dx) > reach_[i];
      }
    if (Utilities::MPI::n_mpi_processes(comm_) > 1)
      rebuild = Utilities::MPI::logical_or(rebuild, comm_);
    if (!rebuild)
      return exchange_states();
    d_                 = &d;
    const double bytes = build_halo(dt);
    d_                 = nullptr;
    build_pending_     = true;
    return bytes;
  }

  double
  Contact::exchange_states()
  {
    copy_own_states();
    if (send_ranks_.empty() && recv_ranks_.empty())
      return 0.;
    std::vector<std::vector<double>> out(send_ranks_.size()), in(recv_ranks_.size());
    std::vector<MPI_Request>         requests;
    requests.reserve(out.size() + in.size());
    constexpr int tag = 2807;
    for (std::size_t q = 0; q < recv_ranks_.size(); ++q)
      {
        in[q].resize(state_record * recv_lists_[q].size());
        requests.emplace_back();
        MPI_Irecv(in[q].data(), static_cast<int>(in[q].size()), MPI_DOUBLE, static_cast<int>(recv_ranks_[q]), tag,
                  comm_, &requests.back());
      }
    double bytes = 0;
    for (std::size_t q = 0; q < send_ranks_.size(); ++q)
      {
        for (const unsigned int k : send_lists_[q])
          out[q].insert(out[q].end(), &own_state_[state_record * k], &own_state_[state_record * k] + state_record);
        bytes += sizeof(double) * out[q].size();
        requests.emplace_back();
        MPI_Isend(out[q].data(), static_cast<int>(out[q].size()), MPI_DOUBLE, static_cast<int>(send_ranks_[q]), tag,
                  comm_, &requests.back());
      }
    MPI_Waitall(static_cast<int>(requests.size()), requests.data(), MPI_STATUSES_IGNORE);
    for (std::size_t q = 0; q < recv_ranks_.size(); ++q)
      for (std::size_t t = 0; t < recv_lists_[q].size(); ++t)
        std::copy_n(&in[q][state_record * t], state_record, &nodes_.state[state_record * recv_lists_[q][t]]);
    return bytes;
  }

  void
  Contact::build_candidates(const unsigned int step, const double dt)
  {
    ++n_rebuilds_;
    last_build_ = step;
    built_      = true;
    const unsigned int n = nodes_.size();
    std::vector<Vec3>  x(n);
    for (unsigned int i = 0; i < n; ++i)
      x[i] = nodes_.position(i);
    x_build_ = x;
    // Reach of each node until the next build: half the skin, or what it covers in reach_steps
    // steps at its present speed if more (fast debris). A pair or a segment is a candidate when
    // the two reaches together could close its distance; the list stays complete while no node
    // has moved more than its reach (the rebuild rule).
    const double base = 0.5 * skin_used_;
    reach_.resize(n);
    for (unsigned int i = 0; i < n; ++i)
      {
        const double *v = &nodes_.state[state_record * i + 3];
        reach_[i]       = std::max(base, reach_steps * dt * std::sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2]));
      }
    double largest_radius = 0;
    for (const auto &p : nodes_.nodes)
      largest_radius = std::max(largest_radius, p.radius);
    const SearchContext context{nodes_, x, reach_, base, largest_radius, bonds_};
    for (auto &in : interactions_)
      in->build(context);
  }

  ContactResult
  Contact::add_forces(const unsigned int step, const double dt, mesh::Vector &f)
  {
    ContactResult result;
    if (interactions_.empty())
      return result;
    // Bonds broken and particles freed since the last step (what the bond filter sees).
    const BondNews news = bonds_.sync(particles_->broken_bonds(), particles_->free_particles());
    if (build_pending_)
      {
        build_candidates(step, dt);
        build_pending_ = false;
      }
    else
      // Bonds broke since the last step and the candidates were not rebuilt: their pairs join
      // the candidates.
      for (auto &in : interactions_)
        in->wake(news);

    std::fill(force_.begin(), force_.end(), 0.);
    ForceSink sink(force_, friction_velocity_);
    for (auto &in : interactions_)
      in->add_forces(nodes_, step, dt, sink);
    wall_force_ = sink.wall_force;

    // The forces of this rank's pairs on its own nodes; those on halo nodes go to their owners
    // at accumulate().
    own_force_old_.swap(own_force_);
    for (std::size_t k = 0; k < own_.size(); ++k)
      for (unsigned int c = 0; c < 3; ++c)
        {
          own_force_[3 * k + c] = force_[3 * own_index_[k] + c];
          f.local_element(owned_local_dof_[k] + c) += own_force_[3 * k + c];
        }
    friction_energy_ += rounded_product(sink.friction_power, dt);
    damping_energy_ += rounded_product(sink.damping_power, dt);
    stored_energy_ = sink.stored;
    result.stable_dt = stable_dt_;
    return result;
  }

  double
  Contact::accumulate(mesh::Vector &f)
  {
    if (interactions_.empty())
      return 0.;
    double bytes = 0;
    if (!send_ranks_.empty() || !recv_ranks_.empty())
      {
        // The reverse of the exchange: forces on halo nodes to their owners.
        std::vector<std::vector<double>> out(recv_ranks_.size()), in(send_ranks_.size());
        std::vector<MPI_Request>         requests;
        constexpr int                    tag = 2808;
        for (std::size_t q = 0; q < send_ranks_.size(); ++q)
          {
            in[q].resize(3 * send_lists_[q].size());
            requests.emplace_back();
            MPI_Irecv(in[q].data(), static_cast<int>(in[q].size()), MPI_DOUBLE, static_cast<int>(send_ranks_[q]), tag,
                      comm_, &requests.back());
          }
        for (std::size_t q = 0; q < recv_ranks_.size(); ++q)
          {
            for (const unsigned int i : recv_lists_[q])
              out[q].insert(out[q].end(), &force_[3 * i], &force_[3 * i] + 3);
            bytes += sizeof(double) * out[q].size();
            requests.emplace_back();
            MPI_Isend(out[q].data(), static_cast<int>(out[q].size()), MPI_DOUBLE, static_cast<int>(recv_ranks_[q]),
                      tag, comm_, &requests.back());
          }
        MPI_Waitall(static_cast<int>(requests.size()), requests.data(), MPI_STATUSES_IGNORE);
        for (std::size_t q = 0; q < send_ranks_.size(); ++q)
          for (std::size_t t = 0; t < send_lists_[q].size(); ++t)
            {
              const unsigned int k = send_lists_[q][t];
              for (unsigned int c = 0; c < 3; ++c)
                {
                  own_force_[3 * k + c] += in[q][3 * t + c];
                  f.local_element(owned_local_dof_[k] + c) += in[q][3 * t + c];
                }
            }
      }
    // Contact work on this rank's nodes (trapezoid over the displacement).
    const bool first = x_old_.empty();
    if (first)
      x_old_.assign(3 * own_.size(), 0.);
    // (A local sum: the member would be stored and reloaded at every term; same order, same value.)
    double energy = energy_;
    for (std::size_t k = 0; k < own_.size(); ++k)
      for (unsigned int c = 0; c < 3; ++c)
        {
          const double x = own_state_[state_record * k + c];
          if (!first && !std::isnan(x_old_[3 * k + c]))
            energy -= 0.5 * (own_force_old_[3 * k + c] + own_force_[3 * k + c]) * (x - x_old_[3 * k + c]);
          x_old_[3 * k + c] = x;
        }
    energy_ = energy;
    return bytes;
  }

  namespace
  {
    template <typename T>
    void
    put_lists(base::BinaryWriter &out, const std::vector<unsigned int> &ranks, const std::vector<std::vector<T>> &lists)
    {
      out.put(ranks);
      out.put(static_cast<std::uint64_t>(lists.size()));
      for (const auto &l : lists)
        out.put(l);
    }

    template <typename T>
    void
    get_lists(base::BinaryReader &in, std::vector<unsigned int> &ranks, std::vector<std::vector<T>> &lists)
    {
      in.get(ranks);
      lists.resize(in.get<std::uint64_t>());
      for (auto &l : lists)
        in.get(l);
    }
  } // namespace

  void
  Contact::save(base::BinaryWriter &out) const
  {
    out.put(std::string("contact"));
    out.put(static_cast<std::uint64_t>(own_.size()));
    // The halo: node records (owned flag apart), segments, state.
    std::vector<double>        records;
    std::vector<unsigned char> owned;
    for (const auto &n : nodes_.nodes)
      {
        pack_node(n, records);
        owned.push_back(n.owned);
      }
    std::vector<double> segments;
    for (const auto &g : nodes_.segments)
      segments.insert(segments.end(), {double(g.node[0]), double(g.node[1]), double(g.node[2]), double(g.node[3]),
                                       g.stiffness, double(g.body)});
    out.put(records);
    out.put(owned);
    out.put(segments);
    out.put(nodes_.state);
    out.put(own_index_);
    put_lists(out, send_ranks_, send_lists_);
    put_lists(out, recv_ranks_, recv_lists_);
    out.put(force_);
    out.put(own_force_);
    out.put(own_force_old_);
    out.put(x_old_);
    out.put(x_build_);
    out.put(reach_);
    bonds_.save(out);
    out.put(static_cast<std::uint64_t>(interactions_.size()));
    for (const auto &in : interactions_)
      in->save(out);
    out.put(last_build_);
    out.put(built_);
    out.put(halo_stale_);
    out.put(stable_dt_);
    out.put(n_rebuilds_);
    out.put(energy_);
    out.put(friction_energy_);
    out.put(damping_energy_);
    out.put(wall_force_);
  }

  void
  Contact::load(base::BinaryReader &in)
  {
    in.expect("contact");
    if (in.get<std::uint64_t>() != own_.size())
      throw std::runtime_error("the contact nodes of the checkpoint differ from this scene's");
    std::vector<double>        records, segments;
    std::vector<unsigned char> owned;
    in.get(records);
    in.get(owned);
    in.get(segments);
    if (records.size() != node_record * owned.size() || segments.size() % 6 != 0)
      throw std::runtime_error("the contact halo of the checkpoint is damaged");
    nodes_ = ContactNodes();
    for (std::size_t i = 0; i < owned.size(); ++i)
      {
        nodes_.nodes.push_back(unpack_node(&records[node_record * i]));
        nodes_.nodes.back().owned = owned[i] != 0;
      }
    for (std::size_t p = 0; p < segments.size(); p += 6)
      {
        ContactSegment g;
        for (unsigned int v = 0; v < 4; ++v)
          g.node[v] = static_cast<unsigned int>(segments[p + v]);
        g.stiffness = segments[p + 4];
        g.body      = static_cast<unsigned int>(segments[p + 5]);
        nodes_.segments.push_back(g);
      }
    in.get(nodes_.state);
    in.get(own_index_);
    if (own_index_.size() != own_.size())
      throw std::runtime_error("the contact nodes of the checkpoint differ from this scene's");
    for (std::size_t k = 0; k < own_.size(); ++k)
      if (own_index_[k] >= nodes_.size() || nodes_.nodes[own_index_[k]].dof != own_[k].dof)
        throw std::runtime_error("the contact nodes of the checkpoint differ from this scene's");
    get_lists(in, send_ranks_, send_lists_);
    get_lists(in, recv_ranks_, recv_lists_);
    in.get(force_);
    in.get(own_force_);
    in.get(own_force_old_);
    in.get(x_old_);
    in.get(x_build_);
    in.get(reach_);
    for (auto &interaction : interactions_)
      interaction->reset(nodes_);
    bonds_.reset(nodes_);
    bonds_.load(in);
    if (in.get<std::uint64_t>() != interactions_.size())
      throw std::runtime_error("the contact interactions of the checkpoint differ from this scene's");
    for (auto &interaction : interactions_)
      interaction->load(in);
    in.get(last_build_);
    in.get(built_);
    in.get(halo_stale_);
    in.get(stable_dt_);
    in.get(n_rebuilds_);
    in.get(energy_);
    in.get(friction_energy_);
    in.get(damping_energy_);
    in.get(wall_force_);
    stable_stale_  = false;
    build_pending_ = false;
    pending_       = Pending();
    own_state_.assign(state_record * own_.size(), 0.);
  }

  Contact::PortableState
  Contact::portable_state(const std::function<unsigned long long(unsigned long long)> &key_of_node) const
  {
    PortableState p;
    for (const auto &n : nodes_.nodes)
      p.keys.push_back(key_of_node(n.dof / 3));
    NodeNaming naming;
    naming.name = [&](const unsigned int i) { return p.keys[i]; };
    for (const auto &in : interactions_)
      {
        base::BinaryWriter w;
        in->write_state(w, nodes_, naming);
        p.interactions.push_back(w.str());
      }
    for (std::size_t k = 0; k < own_.size() && 3 * k < x_old_.size(); ++k)
      {
        p.owned_keys.push_back(key_of_node(own_[k].dof / 3));
        for (unsigned int c = 0; c < 3; ++c)
          {
            p.x_old.push_back(x_old_[3 * k + c]);
            p.force.push_back(own_force_[3 * k + c]);
          }
      }
    p.last_build      = last_build_;
    p.n_rebuilds      = n_rebuilds_;
    p.energy          = energy_;
    p.friction_energy = friction_energy_;
    p.damping_energy  = damping_energy_;
    return p;
  }

  void
  Contact::restore_portable(const std::vector<PortableState>                              &states,
                            const std::function<unsigned long long(unsigned long long)> &node_of_key,
                            const double                                                 energy)
  {
    if (states.empty())
      return;
    const bool root = Utilities::MPI::this_mpi_process(comm_) == 0;
    pending_        = Pending();
    pending_.dof_of_name = [node_of_key](const unsigned long long key) { return 3 * node_of_key(key); };
    std::unordered_map<unsigned long long, std::pair<const double *, const double *>> last_of_key; // x, force
    double friction = 0, damping = 0;
    for (const auto &st : states)
      {
        if (st.interactions.size() != interactions_.size() || st.force.size() != 3 * st.owned_keys.size())
          throw std::runtime_error("the contact state of the checkpoint differs from this scene's");
        std::unordered_map<unsigned long long, bool> writer_owned;
        for (const auto key : st.owned_keys)
          writer_owned.emplace(key, true);
        pending_.dofs.emplace_back();
        pending_.owned.emplace_back();
        for (const auto key : st.keys)
          {
            pending_.dofs.back().push_back(3 * node_of_key(key));
            pending_.owned.back().push_back(writer_owned.count(key) ? 1 : 0);
          }
        pending_.interactions.push_back(st.interactions);
        for (std::size_t k = 0; k < st.owned_keys.size(); ++k)
          last_of_key[st.owned_keys[k]] = {&st.x_old[3 * k], &st.force[3 * k]};
        friction += st.friction_energy;
        damping += st.damping_energy;
      }
    std::unordered_map<unsigned long long, unsigned long long> key_of_node;
    for (const auto &[key, last] : last_of_key)
      key_of_node.emplace(node_of_key(key), key);
    x_old_.assign(3 * own_.size(), 0.);
    for (std::size_t k = 0; k < own_.size(); ++k)
      {
        const auto key = key_of_node.find(own_[k].dof / 3);
        if (key == key_of_node.end())
          {
            x_old_.clear(); // no contact work for one step
            break;
          }
        const auto &last = last_of_key.at(key->second);
        std::copy_n(last.first, 3, &x_old_[3 * k]);
        std::copy_n(last.second, 3, &own_force_[3 * k]);
      }
    built_           = false;
    last_build_      = states.front().last_build;
    n_rebuilds_      = states.front().n_rebuilds;
    energy_          = energy;
    friction_energy_ = root ? friction : 0.;
    damping_energy_  = root ? damping : 0.;
  }
} // namespace shard::contact
