// SPDX-License-Identifier: LGPL-2.1-or-later
#include <shard/base/binary_archive.h>
#include <shard/base/sections.h>
#include <shard/contact/contact.h>

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
    /// Doubles per segment in the set-up table: 4 node DOFs, stiffness, body, spacing.
    constexpr unsigned int segment_record = 7;
    /// Doubles per node in the step exchange: x and v.
    constexpr unsigned int state_record = 6;

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

  void
  Contact::prepare(const mesh::Discretization &discretization, const materials::MaterialLibrary &materials,
                   const particles::ParticleSet &particles, const std::vector<bool> &converted_cells,
                   const mesh::Vector &mass, const base::PrmSource &source)
  {
    comm_      = discretization.communicator();
    particles_ = &particles;
    // A second call (after a conversion) keeps the state of the contacts that go on.
    const Carried carried = carry();
    const auto &bodies = discretization.bodies();
    const auto  body_index = [&](const std::string &name, const std::string &key) {
      for (unsigned int b = 0; b < bodies.size(); ++b)
        if (bodies[b].name == name)
          return b;
      source.fail(key, name, "a body of 'B - Mesh/body names'.");
    };
    interactions_.clear();
    std::vector<bool> involved(bodies.size(), false);
    for (const auto &name : names_)
      {
        Interaction s = settings_.at(name);
        const std::string key = sections::contact + "/" + name + "/";
        s.type = s.type_text == "particles" ? Type::particles : s.type_text == "rigid wall" ? Type::rigid_wall :
                                                                                              Type::node_to_surface;
        if (base::split(s.body_text, ',').empty())
          source.fail(key + "body", s.body_text, "at least one body name of 'B - Mesh/body names'.");
        if (s.type == Type::node_to_surface && s.target.empty())
          source.fail(key + "target", s.target, "the name of an FE body.");
        for (const auto &b : base::split(s.body_text, ','))
          {
            s.bodies.push_back(body_index(b, key + "body"));
            involved[s.bodies.back()] = true;
          }
        if (s.type == Type::node_to_surface)
          {
            s.target_body = body_index(s.target, key + "target");
            if (particles.is_particle_body(s.target_body))
              source.fail(key + "target", s.target, "an FE body (particle bodies meet through type 'particles').");
            involved[s.target_body] = true;
          }
        if (s.type == Type::rigid_wall)
          {
            s.point  = base::parse_point(s.wall_point);
            s.normal = base::parse_point(s.wall_normal);
            const double l = norm(s.normal);
            for (auto &c : s.normal)
              c /= l;
          }
        interactions_.push_back(s);
      }
    if (interactions_.empty())
      return;

    // This rank's contact nodes and segments.
    const auto        &pt = *discretization.partitioner();
    const auto        &X  = discretization.reference_positions();
    std::map<unsigned long long, std::array<double, node_record>> mine; // by global DOF
    const auto bulk_of = [&](const unsigned int b) { return materials.get(bodies[b].material).elastic_moduli()[0]; };
    const auto add_node = [&](const types::global_dof_index g, const unsigned int b, const double h,
                              const bool is_particle, const Vec3 &support) {
      if (!pt.in_local_range(g))
        return;
      const unsigned int j   = pt.global_to_local(g);
      auto               it  = mine.find(g);
      if (it == mine.end())
        {
          std::array<double, node_record> r{};
          r[0] = double(g);
          for (unsigned int c = 0; c < 3; ++c)
            r[1 + c] = X.local_element(j + c);
          r[4]  = mass.local_element(j);
          r[5]  = is_particle ? 0.5 * h : 0.;
          r[6]  = bulk_of(b);
          r[7]  = h;
          r[8]  = b;
          r[9]  = is_particle;
          for (unsigned int c = 0; c < 3; ++c)
            r[10 + c] = support[c];
          it = mine.emplace(g, r).first;
        }
      it->second[7] = std::max(it->second[7], h);
    };
    for (unsigned int i = 0; i < particles.n_owned(); ++i)
      if (involved[particles.body(i)])
        {
          const auto &h = particles.spacing(i);
          const Vec3  support = particles.support_radius(i);
          add_node(pt.local_to_global(particles.local_dof(i)), particles.body(i), std::min({h[0], h[1], h[2]}), true,
                   support);
        }
    std::vector<double> segment_table; // 4 node DOFs, stiffness, body, spacing
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
            const Point<3> x0 = face->vertex(0), x1 = face->vertex(1), x3 = face->vertex(3);
            const Tensor<1, 3> n = cross_product_3d(x1 - x0, x3 - x0);
            if (n * (face->center() - centre) < 0)
              std::swap(order[1], order[3]);
            const double area = face->measure();
            for (const unsigned int v : order)
              {
                const auto g = face->vertex_dof_index(v, 0);
                segment_table.push_back(double(g));
                add_node(g, b, h, false, Vec3{{0, 0, 0}});
              }
            segment_table.push_back(area * area / volume * bulk_of(b));
            segment_table.push_back(b);
            segment_table.push_back(h);
          }
      }
    // Particle bodies' nodes on intact cells are FE nodes; those of converted cells were added
    // as particles above.

    // Segments first: a face node may be owned by a rank that owns no face with it; the owner
    // adds it from the gathered segments. Then the nodes, in rank order (each rank's sorted by
    // DOF).
    const auto all_segments = Utilities::MPI::all_gather(comm_, segment_table);
    for (const auto &part : all_segments)
      for (std::size_t p = 0; p < part.size(); p += segment_record)
        for (unsigned int v = 0; v < 4; ++v)
          add_node(static_cast<types::global_dof_index>(part[p + v]), static_cast<unsigned int>(part[p + 5]),
                   part[p + 6], false, Vec3{{0, 0, 0}});
    std::vector<double> flat;
    for (const auto &[g, r] : mine)
      flat.insert(flat.end(), r.begin(), r.end());
    const auto all_nodes = Utilities::MPI::all_gather(comm_, flat);
    const unsigned int rank = Utilities::MPI::this_mpi_process(comm_);
    nodes_.clear();
    counts_.assign(all_nodes.size(), 0);
    displs_.assign(all_nodes.size(), 0);
    std::map<unsigned long long, unsigned int> index_of;
    for (unsigned int r = 0; r < all_nodes.size(); ++r)
      {
        if (r == rank)
          owned_begin_ = nodes_.size();
        displs_[r] = state_record * nodes_.size();
        for (std::size_t p = 0; p < all_nodes[r].size(); p += node_record)
          {
            const double *a = &all_nodes[r][p];
            Node          n;
            n.dof     = static_cast<unsigned long long>(a[0]);
            n.X       = Vec3{{a[1], a[2], a[3]}};
            n.mass    = a[4];
            n.radius  = a[5];
            n.bulk    = a[6];
            n.spacing = a[7];
            n.body    = static_cast<unsigned int>(a[8]);
            n.particle = a[9] > 0;
            n.support  = Vec3{{a[10], a[11], a[12]}};
            index_of[n.dof] = nodes_.size();
            nodes_.push_back(n);
          }
        counts_[r] = state_record * nodes_.size() - displs_[r];
      }
    owned_local_dof_.clear();
    for (const auto &[g, r] : mine)
      owned_local_dof_.push_back(pt.global_to_local(g));
    segments_.clear();
    for (const auto &part : all_segments)
      for (std::size_t p = 0; p < part.size(); p += segment_record)
        {
          Segment s;
          for (unsigned int v = 0; v < 4; ++v)
            s.node[v] = index_of.at(static_cast<unsigned long long>(part[p + v]));
          s.stiffness = part[p + 4];
          s.body      = static_cast<unsigned int>(part[p + 5]);
          segments_.push_back(s);
        }
    state_.assign(state_record * nodes_.size(), 0.);
    force_.assign(3 * nodes_.size(), 0.);
    force_old_.assign(3 * nodes_.size(), 0.);
    x_old_.clear();
    candidates_.assign(interactions_.size(), {});
    dormant_.assign(interactions_.size(), {});
    offset_.assign(interactions_.size(), {});
    entry_depth_.assign(interactions_.size(), std::vector<double>(nodes_.size(), -1.));
    penetration_.assign(interactions_.size(), std::vector<double>(nodes_.size(), 0.));
    segment_.assign(interactions_.size(), std::vector<int>(nodes_.size(), -1));
    warned_deep_.resize(interactions_.size(), false);
    plane_stamp_.clear();
    planes_.clear();
    best_.assign(nodes_.size(), -1);
    outside_.assign(nodes_.size(), 1e300);
    contact_normal_.assign(interactions_.size(), std::vector<double>(3 * nodes_.size(), 0.));
    previous_slaves_.assign(interactions_.size(), {});
    built_ = false;
    node_of_particle_.clear();
    for (unsigned int i = 0; i < nodes_.size(); ++i)
      if (nodes_[i].particle)
        node_of_particle_.emplace(nodes_[i].dof / 3, i);
    seen_broken_.clear();
    seen_free_.clear();
    free_node_.assign(nodes_.size(), 0);
    broken_partners_.assign(nodes_.size(), {});

    // Skin and the critical step of the stiffest spring each node can meet.
    double smallest = 1e300;
    for (const auto &n : nodes_)
      smallest = std::min(smallest, n.spacing);
    skin_used_ = skin_ > 0 ? skin_ : smallest;
    stable_dt_ = 1e300;
    for (const auto &s : interactions_)
      {
        // Central differences with a dashpot of ratio zeta: dt <= (2 / omega) (sqrt(1 + zeta^2) - zeta).
        const double damped    = std::sqrt(1. + s.damping * s.damping) - s.damping;
        double       k_segment = 0;
        if (s.type == Type::node_to_surface)
          for (const auto &g : segments_)
            if (g.body == s.target_body || (s.symmetric && std::count(s.bodies.begin(), s.bodies.end(), g.body)))
              k_segment = std::max(k_segment, s.penalty * g.stiffness);
        // A segment node carries the reactions of the slaves around it: up to about four
        // springs of the segment stiffness at once.
        // (Not for a rigid target: its nodes move with the mass of the whole body.)
        if (s.type == Type::node_to_surface && !materials.get(bodies[s.target_body].material).rigid())
          for (const auto &g : segments_)
            if (g.body == s.target_body)
              for (const unsigned int a : g.node)
                if (nodes_[a].mass > 0)
                  stable_dt_ = std::min(stable_dt_, damped * 2. * std::sqrt(nodes_[a].mass / (4. * s.penalty * g.stiffness)));
        for (const auto &n : nodes_)
          if (std::count(s.bodies.begin(), s.bodies.end(), n.body) && n.mass > 0)
            {
              // Two masses on one spring: the reduced mass m/2, except against a rigid wall. A
              // node of a symmetric pair is a slave and a segment node at once: twice the spring.
              const double k = s.type == Type::node_to_surface ? k_segment * (s.symmetric ? 2. : 1.) :
                                                                 s.penalty * n.bulk * n.spacing;
              const double m = s.type == Type::rigid_wall ? n.mass : 0.5 * n.mass;
              if (k > 0)
                stable_dt_ = std::min(stable_dt_, damped * 2. * std::sqrt(m / k));
            }
      }
    restore(carried);
  }

  std::array<unsigned long long, 4>
  Contact::segment_dofs(const unsigned int g) const
  {
    std::array<unsigned long long, 4> dofs;
    for (unsigned int v = 0; v < 4; ++v)
      dofs[v] = nodes_[segments_[g].node[v]].dof + 1; // 0 stands for no segment
    std::sort(dofs.begin(), dofs.end());
    return dofs;
  }

  Contact::Carried
  Contact::carry() const
  {
    Carried c;
    if (nodes_.empty() || interactions_.empty())
      return c;
    const std::size_t n = nodes_.size();
    c.dof.resize(n);
    for (std::size_t i = 0; i < n; ++i)
      c.dof[i] = nodes_[i].dof;
    c.force          = force_;
    c.entry_depth    = entry_depth_;
    c.penetration    = penetration_;
    c.segment.resize(segment_.size());
    for (std::size_t s = 0; s < segment_.size(); ++s)
      for (std::size_t i = 0; i < n; ++i)
        c.segment[s].push_back(segment_[s][i] < 0 ? std::array<unsigned long long, 4>{} :
                                                    segment_dofs(static_cast<unsigned int>(segment_[s][i])));
    c.contact_normal = contact_normal_;
    c.previous_slaves.resize(previous_slaves_.size());
    for (std::size_t s = 0; s < previous_slaves_.size(); ++s)
      for (const unsigned int i : previous_slaves_[s])
        c.previous_slaves[s].push_back(nodes_[i].dof);
    c.pairs.resize(interactions_.size());
    c.offsets.resize(interactions_.size());
    for (std::size_t s = 0; s < interactions_.size() && s < offset_.size(); ++s)
      for (std::size_t q = 0; q < candidates_[s].size() && q < offset_[s].size(); ++q)
        if (interactions_[s].type == Type::particles && offset_[s][q] >= 0)
          {
            c.pairs[s].push_back({{nodes_[candidates_[s][q][0]].dof, nodes_[candidates_[s][q][1]].dof}});
            c.offsets[s].push_back(offset_[s][q]);
          }
    for (std::size_t k = 0; k < owned_local_dof_.size() && 3 * k < x_old_.size(); ++k)
      {
        c.owned_dof.push_back(nodes_[owned_begin_ + k].dof);
        c.x_old.insert(c.x_old.end(), &x_old_[3 * k], &x_old_[3 * k] + 3);
      }
    c.n_interactions = interactions_.size();
    return c;
  }

  void
  Contact::restore(const Carried &c)
  {
    if (c.dof.empty() || c.n_interactions != interactions_.size())
      return;
    std::unordered_map<unsigned long long, unsigned int> index_of;
    for (unsigned int i = 0; i < nodes_.size(); ++i)
      index_of.emplace(nodes_[i].dof, i);
    const auto index = [&](const unsigned long long dof) {
      const auto it = index_of.find(dof);
      return it == index_of.end() ? -1 : static_cast<int>(it->second);
    };
    std::map<std::array<unsigned long long, 4>, int> segment_of;
    for (unsigned int g = 0; g < segments_.size(); ++g)
      segment_of.emplace(segment_dofs(g), static_cast<int>(g));
    for (std::size_t k = 0; k < c.dof.size(); ++k)
      {
        const int i = index(c.dof[k]);
        if (i < 0)
          continue;
        for (unsigned int d = 0; d < 3; ++d)
          force_[3 * i + d] = c.force[3 * k + d];
        for (unsigned int s = 0; s < interactions_.size(); ++s)
          {
            entry_depth_[s][i] = c.entry_depth[s][k];
            penetration_[s][i] = c.penetration[s][k];
            const auto it      = segment_of.find(c.segment[s][k]);
            segment_[s][i]     = it == segment_of.end() ? -1 : it->second;
            for (unsigned int d = 0; d < 3; ++d)
              contact_normal_[s][3 * i + d] = c.contact_normal[s][3 * k + d];
          }
      }
    for (unsigned int s = 0; s < interactions_.size(); ++s)
      {
        for (const auto dof : c.previous_slaves[s])
          if (index(dof) >= 0)
            previous_slaves_[s].push_back(index(dof));
        // The next build (built_ is false) keeps the offsets of the pairs it finds again; both
        // orientations, as restore_portable() (the build lists a pair by the node that found it).
        for (std::size_t q = 0; q < c.pairs[s].size(); ++q)
          {
            const int a = index(c.pairs[s][q][0]), b = index(c.pairs[s][q][1]);
            if (a < 0 || b < 0)
              continue;
            candidates_[s].push_back({{static_cast<unsigned int>(a), static_cast<unsigned int>(b)}});
            candidates_[s].push_back({{static_cast<unsigned int>(b), static_cast<unsigned int>(a)}});
            offset_[s].push_back(c.offsets[s][q]);
            offset_[s].push_back(c.offsets[s][q]);
          }
      }
    // Positions of the last step of this rank's nodes; a node new to the contact has none (NaN:
    // no work booked for it in the next step, when its force is still 0 from its entry offset).
    std::unordered_map<unsigned long long, const double *> x_of;
    for (std::size_t k = 0; k < c.owned_dof.size(); ++k)
      x_of.emplace(c.owned_dof[k], &c.x_old[3 * k]);
    if (!c.owned_dof.empty() || !owned_local_dof_.empty())
      {
        x_old_.assign(3 * owned_local_dof_.size(), std::numeric_limits<double>::quiet_NaN());
        for (std::size_t k = 0; k < owned_local_dof_.size(); ++k)
          {
            const auto it = x_of.find(nodes_[owned_begin_ + k].dof);
            if (it != x_of.end())
              std::copy(it->second, it->second + 3, &x_old_[3 * k]);
          }
      }
  }

  void
  Contact::exchange(const mesh::Vector &d, const mesh::Vector &v)
  {
    if (interactions_.empty())
      return;
    std::vector<double> mine(state_record * owned_local_dof_.size());
    for (std::size_t k = 0; k < owned_local_dof_.size(); ++k)
      {
        const Node &n = nodes_[owned_begin_ + k];
        for (unsigned int c = 0; c < 3; ++c)
          {
            mine[state_record * k + c]     = n.X[c] + d.local_element(owned_local_dof_[k] + c);
            mine[state_record * k + 3 + c] = v.local_element(owned_local_dof_[k] + c);
          }
      }
    MPI_Allgatherv(mine.data(), static_cast<int>(mine.size()), MPI_DOUBLE, state_.data(), counts_.data(),
                   displs_.data(), MPI_DOUBLE, comm_);
  }

  double
  Contact::segment_frame(const std::array<Vec3, 4> &x, Vec3 &centre, Vec3 &normal)
  {
    for (unsigned int c = 0; c < 3; ++c)
      centre[c] = 0.25 * (x[0][c] + x[1][c] + x[2][c] + x[3][c]);
    const Vec3 d1{{x[2][0] - x[0][0], x[2][1] - x[0][1], x[2][2] - x[0][2]}};
    const Vec3 d2{{x[3][0] - x[1][0], x[3][1] - x[1][1], x[3][2] - x[1][2]}};
    normal = Vec3{{d1[1] * d2[2] - d1[2] * d2[1], d1[2] * d2[0] - d1[0] * d2[2], d1[0] * d2[1] - d1[1] * d2[0]}};
    const double length = norm(normal);
    for (auto &c : normal)
      c /= length > 0 ? length : 1.;
    return length;
  }

  Contact::Plane
  Contact::mean_plane(const std::array<Vec3, 4> &x)
  {
    Plane p;
    if (!(segment_frame(x, p.centre, p.normal) > 0))
      return p;
    double extent = 0;
    for (unsigned int a = 0; a < 4; ++a)
      {
        const Vec3 &xa = x[a], &xb = x[(a + 1) % 4];
        const Vec3  r{{xa[0] - p.centre[0], xa[1] - p.centre[1], xa[2] - p.centre[2]}};
        p.half_width = std::max(p.half_width, std::abs(r[0] * p.normal[0] + r[1] * p.normal[1] + r[2] * p.normal[2]));
        extent       = std::max(extent, norm(r));
        // Triangle (xa, xb, centre), as point_segment takes it: its normal must face n.
        const Vec3 e1{{xb[0] - xa[0], xb[1] - xa[1], xb[2] - xa[2]}};
        const Vec3 e2{{p.centre[0] - xa[0], p.centre[1] - xa[1], p.centre[2] - xa[2]}};
        const Vec3 nt{{e1[1] * e2[2] - e1[2] * e2[1], e1[2] * e2[0] - e1[0] * e2[2], e1[0] * e2[1] - e1[1] * e2[0]}};
        if (!(nt[0] * p.normal[0] + nt[1] * p.normal[1] + nt[2] * p.normal[2] > 0))
          return p;
      }
    // Margin for the edge tolerance of point_segment (barycentric coordinates down to -1e-3).
    p.half_width += 0.01 * extent;
    p.usable = true;
    return p;
  }

  bool
  Contact::bonded(const unsigned int a, const unsigned int b) const
  {
    const Node &p = nodes_[a], &q = nodes_[b];
    if (!p.particle || !q.particle || p.body != q.body || free_node_[a] || free_node_[b])
      return false;
    const auto &partners = broken_partners_[a];
    if (std::find(partners.begin(), partners.end(), b) != partners.end())
      return false;
    // A bond: one particle inside the other's (box) support.
    const auto inside = [&](const unsigned int i, const Node &other) {
      for (unsigned int c = 0; c < 3; ++c)
        if (std::abs(other.X[c] - nodes_[i].X[c]) >= nodes_[i].support[c])
          return false;
      return true;
    };
    return inside(a, q) || inside(b, p);
  }

  Contact::BondNews
  Contact::sync_bonds()
  {
    BondNews    news;
    const auto &broken = particles_->broken_bonds();
    const auto &free   = particles_->free_particles();
    if (broken.size() == seen_broken_.size() && free.size() == seen_free_.size())
      return news;
    std::vector<std::pair<unsigned long long, unsigned long long>> new_bonds;
    std::vector<unsigned long long>                                  new_free;
    std::set_difference(broken.begin(), broken.end(), seen_broken_.begin(), seen_broken_.end(),
                        std::back_inserter(new_bonds));
    std::set_difference(free.begin(), free.end(), seen_free_.begin(), seen_free_.end(), std::back_inserter(new_free));
    seen_broken_ = broken;
    seen_free_   = free;
    const auto node = [&](const unsigned long long id) {
      const auto it = node_of_particle_.find(id);
      return it == node_of_particle_.end() ? ~0u : it->second;
    };
    for (const auto &[a, b] : new_bonds)
      {
        const unsigned int i = node(a), j = node(b);
        if (i == ~0u || j == ~0u)
          continue;
        broken_partners_[i].push_back(j);
        broken_partners_[j].push_back(i);
        news.broken.push_back({{i, j}});
      }
    for (const unsigned long long id : new_free)
      {
        const unsigned int i = node(id);
        if (i == ~0u)
          continue;
        free_node_[i] = 1;
        news.freed.push_back(i);
      }
    return news;
  }

  void
  Contact::wake_broken_pairs(const BondNews &news)
  {
    for (unsigned int s = 0; s < interactions_.size(); ++s)
      {
        if (interactions_[s].type != Type::particles)
          continue;
        Dormant &dormant = dormant_[s];
        if (dormant.offsets.empty())
          continue;
        const auto wake = [&](const unsigned int p) {
          if (dormant.woken[p])
            return;
          dormant.woken[p] = 1;
          candidates_[s].push_back(dormant.pairs[p]);
          offset_[s].push_back(-1.);
        };
        for (const auto &[i, j] : news.broken)
          for (unsigned int t = dormant.offsets[i]; t < dormant.offsets[i + 1]; ++t)
            {
              const auto &pair = dormant.pairs[dormant.of_node[t]];
              if (pair[0] == j || pair[1] == j)
                wake(dormant.of_node[t]);
            }
        for (const unsigned int i : news.freed)
          for (unsigned int t = dormant.offsets[i]; t < dormant.offsets[i + 1]; ++t)
            wake(dormant.of_node[t]);
      }
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
      x[i] = Vec3{{state_[state_record * i], state_[state_record * i + 1], state_[state_record * i + 2]}};
    x_build_ = x;
    // Reach of each node until the next build: half the skin, or what it covers in
    // reach_steps steps at its present speed if more (fast debris). A pair or a segment is a
    // candidate when the two reaches together could close its distance; the list stays
    // complete while no node has moved more than its reach (the rebuild rule).
    const double base = 0.5 * skin_used_;
    reach_.resize(n);
    for (unsigned int i = 0; i < n; ++i)
      {
        const double *v = &state_[state_record * i + 3];
        reach_[i]       = std::max(base, reach_steps * dt * std::sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2]));
      }
    double largest_radius = 0;
    for (const auto &p : nodes_)
      largest_radius = std::max(largest_radius, p.radius);
    for (unsigned int s = 0; s < interactions_.size(); ++s)
      {
        const auto &in = interactions_[s];
        auto       &cand = candidates_[s];
        cand.clear();
        const auto member = [&](const unsigned int i, const std::vector<unsigned int> &list) {
          return std::count(list.begin(), list.end(), nodes_[i].body) > 0;
        };
        if (in.type == Type::rigid_wall)
          {
            for (unsigned int i = 0; i < n; ++i)
              if (member(i, in.bodies) && plane_gap(x[i], in.point, in.normal) < 2. * reach_[i])
                cand.push_back({{i, 0u}});
          }
        else if (in.type == Type::particles)
          {
            Dormant &dormant = dormant_[s];
            dormant          = Dormant();
            std::vector<unsigned char> is_member(n, 0);
            for (unsigned int i = 0; i < n; ++i)
              is_member[i] = nodes_[i].particle && member(i, in.bodies);
            // Each pair is found from the node of larger reach (the smaller index on a tie),
            // whose reach covers both: found holds (finder, other) of the pairs within
            // r_I + r_J + reach_I + reach_J.
            std::vector<std::array<unsigned int, 2>> found;
            const auto close = [&](const unsigned int i, const unsigned int j) {
              const Vec3   dx{{x[j][0] - x[i][0], x[j][1] - x[i][1], x[j][2] - x[i][2]}};
              const double reach = nodes_[i].radius + nodes_[j].radius + reach_[i] + reach_[j];
              const double d2    = dx[0] * dx[0] + dx[1] * dx[1] + dx[2] * dx[2];
              // Clearly farther (most pairs of the sweep) without the root; the root decides
              // near the limit.
              return !(d2 > reach * reach * (1 + 1e-12)) && norm(dx) < reach;
            };
            // The particles of the interaction in a grid of their own (no FE nodes to skip).
            std::vector<unsigned int> members;
            std::vector<Vec3>         members_x;
            for (unsigned int i = 0; i < n; ++i)
              if (is_member[i])
                {
                  members.push_back(i);
                  members_x.push_back(x[i]);
                }
            BinGrid member_grid;
            member_grid.build(members_x, 2. * largest_radius + 2. * base);
            // Two slow particles (reach skin/2) in contact range are closer than the cell edge,
            // 2 r_max + skin: one sweep over neighbouring cells finds them, each pair once. Pairs
            // farther than that are dropped on the member positions, before any look-up by node.
            const double widest_slow = (2. * largest_radius + 2. * base) * (2. * largest_radius + 2. * base) * (1 + 1e-12);
            member_grid.for_each_neighbour_pair([&](const unsigned int p, const unsigned int q) {
              const Vec3  &a = members_x[p], &b = members_x[q];
              const double d0 = b[0] - a[0], d1 = b[1] - a[1], d2 = b[2] - a[2];
              if (d0 * d0 + d1 * d1 + d2 * d2 > widest_slow)
                return;
              const unsigned int i = members[std::min(p, q)], j = members[std::max(p, q)];
              if (reach_[i] == base && reach_[j] == base && close(i, j))
                found.push_back({{i, j}});
            });
            // A fast particle finds the partners of smaller reach around it.
            for (unsigned int i = 0; i < n; ++i)
              {
                if (!is_member[i] || reach_[i] == base)
                  continue;
                const double r = nodes_[i].radius + largest_radius + 2. * reach_[i];
                member_grid.for_each_in_box(Vec3{{x[i][0] - r, x[i][1] - r, x[i][2] - r}},
                                            Vec3{{x[i][0] + r, x[i][1] + r, x[i][2] + r}}, [&](const unsigned int t) {
                                              const unsigned int j = members[t];
                                              if (j == i || reach_[j] > reach_[i] || (reach_[j] == reach_[i] && j < i))
                                                return;
                                              if (close(i, j))
                                                found.push_back({{i, j}});
                                            });
              }
            // In the order of the finder, then of the other (a counting sort by the finder and
            // a short sort per finder): the lists do not depend on the grid's cell order.
            std::vector<unsigned int> first(n + 1, 0);
            for (const auto &f : found)
              ++first[f[0] + 1];
            for (unsigned int i = 0; i < n; ++i)
              first[i + 1] += first[i];
            std::vector<unsigned int> others(found.size());
            {
              std::vector<unsigned int> next(first.begin(), first.end() - 1);
              for (const auto &f : found)
                others[next[f[0]]++] = f[1];
            }
            for (unsigned int i = 0; i < n; ++i)
              {
                std::sort(others.begin() + first[i], others.begin() + first[i + 1]);
                for (unsigned int t = first[i]; t < first[i + 1]; ++t)
                  {
                    const unsigned int a = std::min(i, others[t]), b = std::max(i, others[t]);
                    if (!bonded(a, b))
                      cand.push_back({{a, b}});
                    else
                      dormant.pairs.push_back({{a, b}});
                  }
              }
            dormant.woken.assign(dormant.pairs.size(), 0);
            dormant.offsets.assign(n + 1, 0);
            for (const auto &pair : dormant.pairs)
              ++dormant.offsets[pair[0] + 1], ++dormant.offsets[pair[1] + 1];
            for (unsigned int i = 0; i < n; ++i)
              dormant.offsets[i + 1] += dormant.offsets[i];
            dormant.of_node.resize(dormant.offsets[n]);
            std::vector<unsigned int> next(dormant.offsets.begin(), dormant.offsets.end() - 1);
            for (unsigned int p = 0; p < dormant.pairs.size(); ++p)
              for (const unsigned int i : dormant.pairs[p])
                dormant.of_node[next[i]++] = p;
          }
        else
          {
            // Each segment of the target (and of the bodies when symmetric) against the nodes
            // of the other side near its box: the slow nodes (reach = skin/2) from the
            // segment's side through the node grid, the fast ones from their own side through
            // a grid of the segment centres.
            struct Box
            {
              Vec3   lo, hi, centre, normal;
              double length = 0, depth = 0, reach = 0, extent = 0;
              bool   forward = false;
            };
            std::vector<Box>          boxes;
            std::vector<unsigned int> used;
            for (unsigned int g = 0; g < segments_.size(); ++g)
              {
                const auto &seg = segments_[g];
                Box         b;
                b.forward            = seg.body == in.target_body;
                const bool  backward = in.symmetric && member(seg.node[0], in.bodies);
                if (!b.forward && !backward)
                  continue;
                b.lo = b.hi = x[seg.node[0]];
                std::array<Vec3, 4> xs;
                for (unsigned int v = 0; v < 4; ++v)
                  {
                    const unsigned int a = seg.node[v];
                    xs[v]                = x[a];
                    b.reach              = std::max(b.reach, reach_[a]);
                    for (unsigned int c = 0; c < 3; ++c)
                      b.lo[c] = std::min(b.lo[c], x[a][c]), b.hi[c] = std::max(b.hi[c], x[a][c]);
                  }
                b.length = segment_frame(xs, b.centre, b.normal);
                for (unsigned int c = 0; c < 3; ++c)
                  b.extent = std::max({b.extent, b.hi[c] - b.centre[c], b.centre[c] - b.lo[c]});
                b.depth = nodes_[seg.node[0]].spacing;
                boxes.push_back(b);
                used.push_back(g);
              }
            // Node i can reach segment k before the next build: inside its box grown by the
            // depth and both reaches, and within the slab -depth - reach < (x - c) . n < reach.
            // A slave in contact is followed below the face spacing by its present penetration
            // (add_forces): its segments are found that much deeper.
            const auto  &pen      = penetration_[s];
            const double deepest  = pen.empty() ? 0. : *std::max_element(pen.begin(), pen.end());
            const auto consider = [&](const unsigned int i, const unsigned int k) {
              const Box         &b   = boxes[k];
              const unsigned int g   = used[k];
              const double       r   = reach_[i] + b.reach;
              const double       dp  = b.depth + pen[i];
              const auto        &seg = segments_[g];
              if (std::count(seg.node.begin(), seg.node.end(), i))
                return;
              for (unsigned int c = 0; c < 3; ++c)
                if (x[i][c] < b.lo[c] - dp - r || x[i][c] > b.hi[c] + dp + r)
                  return;
              const double distance = plane_gap(x[i], b.centre, b.normal);
              if (b.length > 0 && (distance > r || distance < -dp - r))
                return;
              const bool slave = b.forward ? member(i, in.bodies) : nodes_[i].body == in.target_body;
              if (slave && (!nodes_[i].particle || b.forward))
                cand.push_back({{i, g}});
            };
            // The slow nodes that can be a slave of some segment of this interaction, in their
            // own grid: a segment's box then holds no nodes of its own body that could not
            // touch it (the projectile's own surface nodes around each of its faces).
            std::vector<unsigned int> slow;
            std::vector<Vec3>         slow_x;
            for (unsigned int i = 0; i < n; ++i)
              if (reach_[i] == base && (member(i, in.bodies) || (in.symmetric && nodes_[i].body == in.target_body)))
                {
                  slow.push_back(i);
                  slow_x.push_back(x[i]);
                }
            BinGrid slow_grid;
            if (!slow.empty())
              slow_grid.build(slow_x, 2. * largest_radius + 2. * base);
            double widest = 0;
            for (unsigned int k = 0; k < boxes.size(); ++k)
              {
                const Box   &b = boxes[k];
                const double r = b.depth + deepest + b.reach + base;
                widest         = std::max(widest, b.extent + b.depth + deepest + b.reach);
                slow_grid.for_each_in_box(Vec3{{b.lo[0] - r, b.lo[1] - r, b.lo[2] - r}},
                                          Vec3{{b.hi[0] + r, b.hi[1] + r, b.hi[2] + r}},
                                          [&](const unsigned int t) { consider(slow[t], k); });
              }
            std::vector<Vec3> centres;
            for (const auto &b : boxes)
              centres.push_back(b.centre);
            BinGrid segment_grid;
            for (unsigned int i = 0; i < n; ++i)
              if (reach_[i] > base && !boxes.empty())
                {
                  if (segment_grid.size() == 0)
                    segment_grid.build(centres, 2. * widest);
                  const double r = widest + reach_[i];
                  segment_grid.for_each_in_box(Vec3{{x[i][0] - r, x[i][1] - r, x[i][2] - r}},
                                               Vec3{{x[i][0] + r, x[i][1] + r, x[i][2] + r}},
                                               [&](const unsigned int k) { consider(i, k); });
                }
          }
      }
  }

  ContactResult
  Contact::add_forces(const unsigned int step, const double dt, mesh::Vector &f)
  {
    ContactResult result;
    if (interactions_.empty())
      return result;
    const unsigned int n = nodes_.size();
    const auto position = [&](const unsigned int i) {
      return Vec3{{state_[state_record * i], state_[state_record * i + 1], state_[state_record * i + 2]}};
    };
    const auto velocity = [&](const unsigned int i) {
      return Vec3{{state_[state_record * i + 3], state_[state_record * i + 4], state_[state_record * i + 5]}};
    };
    // Bonds broken and particles freed since the last step (what bonded() sees).
    const BondNews news = sync_bonds();
    // Rebuild rule: the rebuild interval, or a node moved more than its reach since the last
    // build.
    bool rebuild = !built_ || step >= last_build_ + rebuild_interval_;
    for (unsigned int i = 0; i < n && !rebuild; ++i)
      {
        const Vec3 x = position(i);
        const Vec3 dx{{x[0] - x_build_[i][0], x[1] - x_build_[i][1], x[2] - x_build_[i][2]}};
        rebuild = norm(dx) > reach_[i];
      }
    if (rebuild)
      {
        // Carry the offsets of the particle pairs over to the new candidate lists.
        std::vector<std::unordered_map<unsigned long long, double>> kept(interactions_.size());
        for (unsigned int s = 0; s < interactions_.size(); ++s)
          for (std::size_t p = 0; p < offset_[s].size(); ++p)
            if (offset_[s][p] >= 0)
              kept[s][(static_cast<unsigned long long>(candidates_[s][p][0]) << 32) | candidates_[s][p][1]] =
                offset_[s][p];
        build_candidates(step, dt);
        for (unsigned int s = 0; s < interactions_.size(); ++s)
          {
            offset_[s].assign(candidates_[s].size(), -1.);
            for (std::size_t p = 0; p < candidates_[s].size() && !kept[s].empty(); ++p)
              {
                const auto it =
                  kept[s].find((static_cast<unsigned long long>(candidates_[s][p][0]) << 32) | candidates_[s][p][1]);
                if (it != kept[s].end())
                  offset_[s][p] = it->second;
              }
          }
      }
    // Bonds broke since the last step and the candidates were not rebuilt: their pairs join
    // the candidates.
    if (!rebuild)
      wake_broken_pairs(news);

    force_old_.swap(force_);
    std::fill(force_.begin(), force_.end(), 0.);
    double     friction_power = 0;
    double     damping_power  = 0; // dissipated by the normal dashpots
    double     stored         = 0; // energy in the penalty springs at this configuration
    wall_force_               = 0;
    const auto add            = [&](const unsigned int i, const Vec3 &g, const double w) {
      for (unsigned int c = 0; c < 3; ++c)
        force_[3 * i + c] += w * g[c];
    };
    // Coulomb friction for the relative velocity vr of a pair pressed by fn along normal: added
    // to force, its power booked as dissipation.
    const auto add_friction = [&](const Vec3 &vr, const Vec3 &normal, const double fn, const double mu, Vec3 &force) {
      const Vec3 ft = coulomb_friction(vr, normal, fn, mu, friction_velocity_);
      friction_power -= ft[0] * vr[0] + ft[1] * vr[1] + ft[2] * vr[2];
      for (unsigned int c = 0; c < 3; ++c)
        force[c] += ft[c];
    };
    // Normal force of a spring fn = k g with the dashpot of ratio zeta for reduced mass m and
    // normal approach speed vn (< 0 approaching): max(0, fn - c vn), c = 2 zeta sqrt(k m); the
    // dashpot's power is booked as dissipation (it is >= 0, also where the clipping acts).
    const auto damped_normal = [&](const double fn, const double k, const double m, const double vn,
                                   const double zeta) {
      if (!(zeta > 0) || !(m > 0))
        return fn;
      const double total = std::max(0., fn - 2. * zeta * std::sqrt(k * m) * vn);
      damping_power -= (total - fn) * vn;
      return total;
    };
    for (unsigned int s = 0; s < interactions_.size(); ++s)
      {
        const auto &in = interactions_[s];
        if (in.type == Type::rigid_wall)
          {
            for (const auto &[i, unused] : candidates_[s])
              {
                const double gap = plane_gap(position(i), in.point, in.normal);
                if (gap >= 0)
                  continue;
                const double k      = in.penalty * nodes_[i].bulk * nodes_[i].spacing;
                const double spring = k * (-gap);
                stored += 0.5 * spring * (-gap);
                const Vec3   vi = velocity(i);
                const double fn = damped_normal(spring, k, nodes_[i].mass,
                                                vi[0] * in.normal[0] + vi[1] * in.normal[1] + vi[2] * in.normal[2],
                                                in.damping);
                Vec3         fvec{{fn * in.normal[0], fn * in.normal[1], fn * in.normal[2]}};
                if (in.friction > 0)
                  add_friction(vi, in.normal, fn, in.friction, fvec);
                add(i, fvec, 1.);
                wall_force_ += fn;
              }
          }
        else if (in.type == Type::particles)
          {
            for (std::size_t p = 0; p < candidates_[s].size(); ++p)
              {
                const unsigned int i = candidates_[s][p][0], j = candidates_[s][p][1];
                // Overlap a pair already had when it first met (neighbours whose bond just broke
                // in a compressed zone) is ignored, and forgotten as the pair separates: no
                // energy from nothing (LS-DYNA's IGNORE of initial penetrations).
                double &offset = offset_[s][p];
                // Clearly apart (most candidates): no overlap, so the offset is forgotten.
                {
                  const double *a = &state_[state_record * i], *b = &state_[state_record * j];
                  const double  d0 = b[0] - a[0], d1 = b[1] - a[1], d2 = b[2] - a[2];
                  const double  reach = nodes_[i].radius + nodes_[j].radius;
                  if (d0 * d0 + d1 * d1 + d2 * d2 > reach * reach * (1 + 1e-12))
                    {
                      offset = 0;
                      continue;
                    }
                }
                SphereHit h = sphere_pair(position(i), position(j), nodes_[i].radius, nodes_[j].radius);
                offset         = std::min(offset < 0 ? std::max(h.overlap, 0.) : offset, std::max(h.overlap, 0.));
                h.overlap -= offset;
                if (h.overlap <= 0)
                  continue;
                const double k  = in.penalty * std::min(nodes_[i].bulk, nodes_[j].bulk) *
                                 std::min(nodes_[i].spacing, nodes_[j].spacing);
                const double spring = k * h.overlap;
                stored += 0.5 * spring * h.overlap;
                double fn = spring;
                Vec3   vr{{0, 0, 0}}; // velocity of j relative to i
                if (in.damping > 0 || in.friction > 0)
                  {
                    const Vec3 vi = velocity(i), vj = velocity(j);
                    vr            = Vec3{{vj[0] - vi[0], vj[1] - vi[1], vj[2] - vi[2]}};
                  }
                if (in.damping > 0)
                  {
                    const double mi = nodes_[i].mass, mj = nodes_[j].mass;
                    fn = damped_normal(spring, k, mi + mj > 0 ? mi * mj / (mi + mj) : 0.,
                                       vr[0] * h.normal[0] + vr[1] * h.normal[1] + vr[2] * h.normal[2], in.damping);
                  }
                Vec3 fj{{fn * h.normal[0], fn * h.normal[1], fn * h.normal[2]}};
                if (in.friction > 0)
                  add_friction(vr, h.normal, fn, in.friction, fj);
                add(j, fj, 1.);
                add(i, fj, -1.);
              }
          }
        else
          {
            // Per slave node the segment it penetrates least deeply (the nearest surface).
            std::vector<std::pair<SegmentHit, unsigned int>> hits;
            std::vector<unsigned int>                        slaves;
            // Nodes whose outside_ entry was set this step (reset to 1e300 after the test).
            std::vector<unsigned int> outside_nodes;
            auto &normal_before = contact_normal_[s];
            auto &pen_before    = penetration_[s];
            const auto history  = [&](const unsigned int i) {
              const double *nb = &normal_before[3 * i];
              return nb[0] != 0 || nb[1] != 0 || nb[2] != 0;
            };
            // Whether normal n is of the direction slave i was pressed along at the last step.
            const auto along = [&](const Vec3 &n, const unsigned int i) {
              const double *nb = &normal_before[3 * i];
              return n[0] * nb[0] + n[1] * nb[1] + n[2] * nb[2] >= corner_cosine;
            };
            // How deep a hit may lie: the face spacing, and for a slave in contact its penetration
            // of the last step on top (it is followed however deep it is pressed).
            const auto reach_depth = [&](const unsigned int i, const double depth) {
              return history(i) ? depth + pen_before[i] : depth;
            };
            // Keeps hit h on segment g for slave i if it is less deep than the one kept. (Preferring
            // the faces of the slave's last direction instead was tried: a slave whose first hit was
            // a side face of the target, one face spacing deep, then kept it with that entry offset
            // and no force, and the head-on FE-particle bars at 10 m/s stuck together.)
            const auto keep = [&](const unsigned int i, const SegmentHit &h, const unsigned int g) {
              if (best_[i] < 0)
                {
                  best_[i] = static_cast<int>(hits.size());
                  hits.emplace_back(h, g);
                  slaves.push_back(i);
                  return;
                }
              if (std::abs(h.gap) < std::abs(hits[best_[i]].first.gap))
                hits[best_[i]] = {h, g};
            };
            // Faces of its direction under which a slave in contact lies but onto which it does
            // not project (the dead zone of a valley between faces): tried with a wider edge
            // tolerance below.
            std::vector<std::array<unsigned int, 2>> missed;
            // Per segment (once per step): the mean plane through its centre, the half width
            // of the slab that holds its four nodes, and whether its four triangles face the
            // same way. A point above that slab, or below it by more than the depth, cannot hit
            // any of the triangles, so point_segment is skipped for it.
            plane_stamp_.resize(segments_.size(), ~0u);
            planes_.resize(segments_.size());
            for (const auto &[i, g] : candidates_[s])
              {
                const auto &seg = segments_[g];
                std::array<Vec3, 4> xs;
                for (unsigned int v = 0; v < 4; ++v)
                  xs[v] = position(seg.node[v]);
                const double depth = nodes_[seg.node[0]].spacing;
                Plane       &pl    = planes_[g];
                if (plane_stamp_[g] != step)
                  {
                    plane_stamp_[g] = step;
                    pl              = mean_plane(xs);
                    double r2       = 0;
                    for (const auto &xv : xs)
                      r2 = std::max(r2, (xv[0] - pl.centre[0]) * (xv[0] - pl.centre[0]) +
                                          (xv[1] - pl.centre[1]) * (xv[1] - pl.centre[1]) +
                                          (xv[2] - pl.centre[2]) * (xv[2] - pl.centre[2]));
                    pl.sphere2 = 1.0201 * r2;
                  }
                const double deep = reach_depth(i, depth);
                const Vec3   p    = position(i);
                {
                  const double d0 = p[0] - pl.centre[0], d1 = p[1] - pl.centre[1], d2 = p[2] - pl.centre[2];
                  if (d0 * d0 + d1 * d1 + d2 * d2 > pl.sphere2 + deep * deep)
                    continue;
                }
                double hgt = 0;
                if (pl.usable)
                  {
                    hgt = (p[0] - pl.centre[0]) * pl.normal[0] + (p[1] - pl.centre[1]) * pl.normal[1] +
                          (p[2] - pl.centre[2]) * pl.normal[2];
                    if (hgt > pl.half_width || hgt < -pl.half_width - deep)
                      continue;
                  }
                const SegmentHit h = point_segment(p, xs, deep);
                if (!h.hit)
                  {
                    // Outside this face (the projection is on it): remembered for the nearest-
                    // surface test below.
                    if (h.projected && h.gap >= 0 && h.gap < outside_[i])
                      {
                        if (!(outside_[i] < 1e300))
                          outside_nodes.push_back(i);
                        outside_[i] = h.gap;
                      }
                    if (!h.projected && pl.usable && hgt < 0 && history(i) && along(pl.normal, i))
                      missed.push_back({{i, g}});
                    continue;
                  }
                keep(i, h, g);
              }
            // The dead zone. Where the faces around a node form a valley (seen from outside; an
            // end face that the impact has dimpled), a slave pressed into it projects onto none
            // of them within the edge tolerance. It then lost its contact for a step and was
            // caught by a side face of the target one face spacing deep, with the full spring of
            // that depth (the head-on bars at 100 m/s: 68 J stored from nothing, the run stopped
            // at 6.7 us). A slave in contact keeps the face of its direction it lies under, its
            // contact point clamped onto the face.
            for (const auto &[i, g] : missed)
              {
                if (best_[i] >= 0 && along(planes_[hits[best_[i]].second].normal, i))
                  continue;
                const auto         &seg = segments_[g];
                std::array<Vec3, 4> xs;
                for (unsigned int v = 0; v < 4; ++v)
                  xs[v] = position(seg.node[v]);
                const SegmentHit h = point_segment(position(i), xs, reach_depth(i, nodes_[seg.node[0]].spacing), 0.05);
                if (h.hit)
                  keep(i, h, g);
              }
            // A slave whose contact turns to a face of another direction (a corner of the target)
            // is checked against the nearest surface: if it lies outside some face (its
            // projection on the face, gap >= 0) by less than it penetrates the new face, it left
            // the body through that face, and the new hit (found through the edge tolerance) is
            // not a contact. Without this test a plate node that lifted off the flat end face of a
            // rigid projectile by a fraction of a micrometre, still within the edge tolerance of a
            // side face, counted as penetrating the side face by up to the face spacing and was
            // thrown off at km/s (doc/manual/contact.md, "Corners"). A slave that stays on a face
            // of its direction keeps it (the aligned edges of two bars: the edge nodes lie on the
            // side planes of the target and still press its end face). The faces skipped above
            // for such a slave (above their slab by less than its penetration) are projected here.
            const auto turned = [&](const unsigned int i) {
              return history(i) && !along(planes_[hits[best_[i]].second].normal, i);
            };
            bool any_turned = false;
            for (const unsigned int i : slaves)
              any_turned = any_turned || turned(i);
            if (any_turned)
              {
                for (const auto &[i, g] : candidates_[s])
                  {
                    if (best_[i] < 0 || !turned(i))
                      continue;
                    const double pen = std::min(-hits[best_[i]].first.gap, outside_[i]);
                    const Plane &pl  = planes_[g];
                    if (!pl.usable)
                      continue; // projected above whatever its height
                    const Vec3   p = position(i);
                    const double hgt = (p[0] - pl.centre[0]) * pl.normal[0] + (p[1] - pl.centre[1]) * pl.normal[1] +
                                       (p[2] - pl.centre[2]) * pl.normal[2];
                    // Only the faces skipped above as clearly outside, and close enough to matter.
                    if (!(hgt > pl.half_width) || hgt - pl.half_width >= pen)
                      continue;
                    const auto         &seg = segments_[g];
                    std::array<Vec3, 4> xs;
                    for (unsigned int v = 0; v < 4; ++v)
                      xs[v] = position(seg.node[v]);
                    const SegmentHit h = point_segment(p, xs, nodes_[seg.node[0]].spacing);
                    if (h.projected && h.gap >= 0 && h.gap < outside_[i])
                      {
                        if (!(outside_[i] < 1e300))
                          outside_nodes.push_back(i);
                        outside_[i] = h.gap;
                      }
                  }
                std::size_t kept = 0;
                for (const unsigned int i : slaves)
                  if (turned(i) && outside_[i] < -hits[best_[i]].first.gap)
                    best_[i] = -1;
                  else
                    slaves[kept++] = i;
                slaves.resize(kept);
              }
            for (const unsigned int i : outside_nodes)
              outside_[i] = 1e300;
            outside_nodes.clear();
            std::sort(slaves.begin(), slaves.end());
            // A slave that starts a contact already deep (it slid in over the edge of a face)
            // keeps that entry depth as an offset while the contact lasts, so that no energy
            // comes from nothing; a contact that starts at the surface has none. A slave that
            // moves on to another face keeps the penetration it pressed with (its spring's
            // energy), not the depth it finds under the new face: on a faceted curved target
            // (the ogive nose) the depth under the next facet differs, and a particle went from
            // a spring of a few micrometres to one of 1.15 mm in a step, then inverted.
            auto &depth   = entry_depth_[s];
            auto &segment = segment_[s];
            for (const unsigned int i : previous_slaves_[s])
              if (best_[i] < 0)
                {
                  depth[i]   = -1.;
                  segment[i] = -1;
                }
            for (const unsigned int i : slaves)
              {
                const double now = -hits[best_[i]].first.gap;
                const int    g   = static_cast<int>(hits[best_[i]].second);
                if (depth[i] >= 0 && segment[i] != g)
                  {
                    // The spring's energy k eff^2 / 2 goes on: the faces of one target differ in
                    // stiffness (the tip face of the ogive nose is 100 times softer than its
                    // side facets: a particle pressed 3.5 mm into the tip got 1.5 kJ when it
                    // moved on to a side facet with the same penetration).
                    // Its penetration changes in the step by what the relative normal motion
                    // allows, |v_slave - v_face| dt, not by the difference of depth under the two
                    // faces (a slave in the valley between end faces found a side face one face
                    // spacing deep: 68 J from nothing in the head-on bars at 100 m/s).
                    const SegmentHit &h     = hits[best_[i]].first;
                    const Vec3        vi    = velocity(i);
                    double            vr[3] = {vi[0], vi[1], vi[2]};
                    for (unsigned int v = 0; v < 4; ++v)
                      for (unsigned int c = 0; c < 3; ++c)
                        vr[c] -= h.weights[v] * state_[state_record * segments_[g].node[v] + 3 + c];
                    const double motion = 1.5 * dt * std::sqrt(vr[0] * vr[0] + vr[1] * vr[1] + vr[2] * vr[2]);
                    const double change = std::clamp(now - pen_before[i], -motion, motion);
                    const double k_new  = segments_[g].stiffness;
                    const double k_old  = segment[i] >= 0 ? segments_[segment[i]].stiffness : k_new;
                    const double eff    = std::max(0., std::max(0., pen_before[i] - depth[i]) + change);
                    depth[i]            = std::max(0., now - eff * std::sqrt(k_old / k_new));
                  }
                depth[i]   = depth[i] < 0 ? now : std::min(depth[i], now);
                segment[i] = g;
              }
            for (const unsigned int i : previous_slaves_[s])
              if (best_[i] < 0)
                {
                  std::fill_n(&normal_before[3 * i], 3, 0.);
                  pen_before[i] = 0;
                }
            for (const unsigned int i : slaves)
              {
                std::copy_n(planes_[hits[best_[i]].second].normal.begin(), 3, &normal_before[3 * i]);
                pen_before[i] = -hits[best_[i]].first.gap;
              }
            previous_slaves_[s] = slaves;
            for (const unsigned int i : slaves)
              {
                const auto &[h, g] = hits[best_[i]];
                best_[i]           = -1;
                const auto  &seg   = segments_[g];
                const double fn    = in.penalty * seg.stiffness * (-h.gap - depth[i]);
                if (-h.gap - depth[i] > 0.5 * nodes_[seg.node[0]].spacing && !warned_deep_[s])
                  {
                    warned_deep_[s] = true;
                    if (Utilities::MPI::this_mpi_process(comm_) == 0)
                      std::fprintf(stderr,
                                   "shard: warning: contact '%s', step %u: a penalty spring is pressed %.3g m, more "
                                   "than half the face spacing %.3g m. The contact follows the slave, but the penalty "
                                   "is soft for this impact (bodies may pass through); raise 'H - Contact/%s/penalty "
                                   "scale' (doc/manual/contact.md, \"Time step\"). Said once.\n",
                                   names_[s].c_str(), step, -h.gap - depth[i], nodes_[seg.node[0]].spacing,
                                   names_[s].c_str());
                  }
                if (!(fn > 0))
                  continue;
                stored += 0.5 * fn * (-h.gap - depth[i]);
                Vec3 vr{{0, 0, 0}}; // slave velocity relative to the face point
                if (in.friction > 0 || in.damping > 0)
                  {
                    Vec3 vm{{0, 0, 0}};
                    for (unsigned int v = 0; v < 4; ++v)
                      for (unsigned int c = 0; c < 3; ++c)
                        vm[c] += h.weights[v] * state_[state_record * seg.node[v] + 3 + c];
                    const Vec3 vi = velocity(i);
                    vr            = Vec3{{vi[0] - vm[0], vi[1] - vm[1], vi[2] - vm[2]}};
                  }
                double f_normal = fn;
                if (in.damping > 0)
                  {
                    // The face point's mass: the weighted masses of the face nodes.
                    double ms = 0;
                    for (unsigned int v = 0; v < 4; ++v)
                      ms += h.weights[v] * nodes_[seg.node[v]].mass;
                    const double mi = nodes_[i].mass;
                    f_normal        = damped_normal(fn, in.penalty * seg.stiffness, mi + ms > 0 ? mi * ms / (mi + ms) : 0.,
                                                    vr[0] * h.normal[0] + vr[1] * h.normal[1] + vr[2] * h.normal[2],
                                                    in.damping);
                  }
                Vec3 fi{{f_normal * h.normal[0], f_normal * h.normal[1], f_normal * h.normal[2]}};
                if (in.friction > 0)
                  add_friction(vr, h.normal, f_normal, in.friction, fi);
                add(i, fi, 1.);
                for (unsigned int v = 0; v < 4; ++v)
                  add(seg.node[v], fi, -h.weights[v]);
              }
          }
      }

    // Forces of this rank's nodes; contact work on them (trapezoid over the displacement).
    const bool first = x_old_.empty();
    if (first)
      x_old_.assign(3 * owned_local_dof_.size(), 0.);
    // (A local sum: the member would be stored and reloaded at every term; same order, same value.)
    double energy = energy_;
    for (std::size_t k = 0; k < owned_local_dof_.size(); ++k)
      {
        const unsigned int i = owned_begin_ + k;
        for (unsigned int c = 0; c < 3; ++c)
          {
            const double x = state_[state_record * i + c];
            f.local_element(owned_local_dof_[k] + c) += force_[3 * i + c];
            if (!first && !std::isnan(x_old_[3 * k + c]))
              energy -= 0.5 * (force_old_[3 * i + c] + force_[3 * i + c]) * (x - x_old_[3 * k + c]);
            x_old_[3 * k + c] = x;
          }
      }
    energy_ = energy;
    // Friction dissipation (replicated on every rank, counted on rank 0), mid-step velocities.
    if (Utilities::MPI::this_mpi_process(comm_) == 0)
      {
        friction_energy_ += friction_power * dt;
        damping_energy_ += damping_power * dt;
        stored_energy_ = stored;
      }
    result.stable_dt = stable_dt_;
    return result;
  }

  void
  Contact::save(base::BinaryWriter &out) const
  {
    out.put(std::string("contact"));
    out.put(static_cast<std::uint64_t>(nodes_.size()));
    out.put(force_);
    out.put(force_old_);
    out.put(x_old_);
    out.put(x_build_);
    out.put(reach_);
    out.put(seen_broken_);
    out.put(seen_free_);
    out.put(free_node_);
    out.put(broken_partners_);
    out.put(candidates_);
    out.put(static_cast<std::uint64_t>(dormant_.size()));
    for (const auto &d : dormant_)
      {
        out.put(d.pairs);
        out.put(d.woken);
        out.put(d.offsets);
        out.put(d.of_node);
      }
    out.put(offset_);
    out.put(entry_depth_);
    out.put(penetration_);
    out.put(segment_);
    out.put(previous_slaves_);
    out.put(contact_normal_);
    out.put(best_);
    out.put(last_build_);
    out.put(built_);
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
    if (in.get<std::uint64_t>() != nodes_.size())
      throw std::runtime_error("the contact nodes of the checkpoint differ from this scene's");
    in.get(force_);
    in.get(force_old_);
    in.get(x_old_);
    in.get(x_build_);
    in.get(reach_);
    in.get(seen_broken_);
    in.get(seen_free_);
    in.get(free_node_);
    in.get(broken_partners_);
    in.get(candidates_);
    dormant_.resize(in.get<std::uint64_t>());
    for (auto &d : dormant_)
      {
        in.get(d.pairs);
        in.get(d.woken);
        in.get(d.offsets);
        in.get(d.of_node);
      }
    in.get(offset_);
    in.get(entry_depth_);
    in.get(penetration_);
    in.get(segment_);
    in.get(previous_slaves_);
    in.get(contact_normal_);
    in.get(best_);
    in.get(last_build_);
    in.get(built_);
    in.get(n_rebuilds_);
    in.get(energy_);
    in.get(friction_energy_);
    in.get(damping_energy_);
    in.get(wall_force_);
    // The plane cache is per step and is filled again.
    plane_stamp_.clear();
    planes_.clear();
  }

  Contact::PortableState
  Contact::portable_state(const std::function<unsigned long long(unsigned long long)> &key_of_node) const
  {
    PortableState p;
    for (const auto &n : nodes_)
      p.keys.push_back(key_of_node(n.dof / 3));
    p.force       = force_;
    p.entry_depth    = entry_depth_;
    p.penetration    = penetration_;
    p.segment.resize(segment_.size());
    for (std::size_t s = 0; s < segment_.size(); ++s)
      for (std::size_t i = 0; i < nodes_.size(); ++i)
        for (unsigned int v = 0; v < 4; ++v)
          p.segment[s].push_back(segment_[s][i] < 0 ? 0ull : p.keys[segments_[segment_[s][i]].node[v]] + 1);
    p.contact_normal = contact_normal_;
    for (const auto &slaves : previous_slaves_)
      {
        p.previous_slaves.emplace_back();
        for (const unsigned int i : slaves)
          p.previous_slaves.back().push_back(p.keys[i]);
      }
    for (unsigned int s = 0; s < interactions_.size(); ++s)
      {
        p.pairs.emplace_back();
        p.offsets.emplace_back();
        if (interactions_[s].type != Type::particles)
          continue;
        for (std::size_t q = 0; q < candidates_[s].size() && q < offset_[s].size(); ++q)
          if (offset_[s][q] >= 0)
            {
              p.pairs.back().emplace_back(p.keys[candidates_[s][q][0]], p.keys[candidates_[s][q][1]]);
              p.offsets.back().push_back(offset_[s][q]);
            }
      }
    for (std::size_t k = 0; k < owned_local_dof_.size() && 3 * k < x_old_.size(); ++k)
      {
        p.owned_keys.push_back(p.keys[owned_begin_ + k]);
        for (unsigned int c = 0; c < 3; ++c)
          p.x_old.push_back(x_old_[3 * k + c]);
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
    std::unordered_map<unsigned long long, unsigned int> index_of_dof;
    for (unsigned int i = 0; i < nodes_.size(); ++i)
      index_of_dof.emplace(nodes_[i].dof, i);
    const auto index = [&](const unsigned long long key) {
      const auto it = index_of_dof.find(3 * node_of_key(key));
      if (it == index_of_dof.end())
        throw std::runtime_error("contact node " + std::to_string(key) + " of the checkpoint is not a contact node");
      return it->second;
    };
    std::map<std::array<unsigned long long, 4>, int> segment_of;
    for (unsigned int g = 0; g < segments_.size(); ++g)
      segment_of.emplace(segment_dofs(g), static_cast<int>(g));
    const auto &first = states.front();
    if (first.keys.size() != nodes_.size() || first.entry_depth.size() != interactions_.size() ||
        first.contact_normal.size() != interactions_.size())
      throw std::runtime_error("the contact nodes of the checkpoint differ from this scene's");
    for (std::size_t k = 0; k < first.keys.size(); ++k)
      {
        const unsigned int i = index(first.keys[k]);
        for (unsigned int c = 0; c < 3; ++c)
          force_[3 * i + c] = first.force[3 * k + c];
        for (unsigned int s = 0; s < interactions_.size(); ++s)
          {
            entry_depth_[s][i] = first.entry_depth[s][k];
            if (s < first.penetration.size())
              penetration_[s][i] = first.penetration[s][k];
            if (s < first.segment.size() && first.segment[s][4 * k] > 0)
              {
                std::array<unsigned long long, 4> dofs;
                for (unsigned int v = 0; v < 4; ++v)
                  dofs[v] = 3 * node_of_key(first.segment[s][4 * k + v] - 1) + 1;
                std::sort(dofs.begin(), dofs.end());
                const auto it  = segment_of.find(dofs);
                segment_[s][i] = it == segment_of.end() ? -1 : it->second;
              }
            for (unsigned int c = 0; c < 3; ++c)
              contact_normal_[s][3 * i + c] = first.contact_normal[s][3 * k + c];
          }
      }
    for (unsigned int s = 0; s < interactions_.size(); ++s)
      {
        previous_slaves_[s].clear();
        for (const auto key : first.previous_slaves[s])
          previous_slaves_[s].push_back(index(key));
        // Both orientations: the next build keeps an offset by the pair as it finds it.
        candidates_[s].clear();
        offset_[s].clear();
        for (std::size_t q = 0; q < first.pairs[s].size(); ++q)
          {
            const unsigned int a = index(first.pairs[s][q].first), b = index(first.pairs[s][q].second);
            candidates_[s].push_back({{a, b}});
            candidates_[s].push_back({{b, a}});
            offset_[s].push_back(first.offsets[s][q]);
            offset_[s].push_back(first.offsets[s][q]);
          }
      }
    std::unordered_map<unsigned long long, const double *> x_of_key;
    for (const auto &st : states)
      for (std::size_t k = 0; k < st.owned_keys.size(); ++k)
        x_of_key[st.owned_keys[k]] = &st.x_old[3 * k];
    std::unordered_map<unsigned long long, unsigned long long> key_of_node;
    for (const auto key : first.keys)
      key_of_node.emplace(node_of_key(key), key);
    x_old_.assign(3 * owned_local_dof_.size(), 0.);
    for (std::size_t k = 0; k < owned_local_dof_.size(); ++k)
      {
        const auto it = x_of_key.find(key_of_node.at(nodes_[owned_begin_ + k].dof / 3));
        if (it == x_of_key.end())
          {
            x_old_.clear(); // no contact work for one step
            break;
          }
        std::copy(it->second, it->second + 3, &x_old_[3 * k]);
      }
    built_           = false;
    last_build_      = first.last_build;
    n_rebuilds_      = first.n_rebuilds;
    energy_          = energy;
    friction_energy_ = Utilities::MPI::this_mpi_process(comm_) == 0 ? first.friction_energy : 0.;
    damping_energy_  = Utilities::MPI::this_mpi_process(comm_) == 0 ? first.damping_energy : 0.;
    plane_stamp_.clear();
    planes_.clear();
  }
} // namespace shard::contact
