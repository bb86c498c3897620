// SPDX-License-Identifier: LGPL-2.1-or-later
#include <shard/base/binary_archive.h>
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
    /// Doubles per segment in the set-up table: 4 node DOFs, stiffness, body, spacing.
    constexpr unsigned int segment_record = 7;
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
    for (const auto &s : resolve(discretization, materials, particles, source))
      {
        for (const unsigned int b : s.bodies)
          involved[b] = true;
        if (s.type_text == "node to surface")
          involved[s.target_body] = true;
        interactions_.push_back(make_interaction(s));
        interactions_.back()->set_print_notices(speaks);
        if (before.size() > interactions_.size() - 1)
          interactions_.back()->keep_notices(*before[interactions_.size() - 1]);
      }
    if (interactions_.empty())
      return;

    gather(discretization, materials, particles, converted_cells, mass, involved);
    force_.assign(3 * nodes_.size(), 0.);
    force_old_.assign(3 * nodes_.size(), 0.);
    x_old_.clear();
    for (auto &in : interactions_)
      in->reset(nodes_);
    built_ = false;
    bonds_.reset(nodes_);

    // Skin and the critical step of the stiffest spring each node can meet.
    double smallest = 1e300;
    for (const auto &n : nodes_.nodes)
      smallest = std::min(smallest, n.spacing);
    skin_used_ = skin_ > 0 ? skin_ : smallest;
    stable_dt_ = 1e300;
    for (const auto &in : interactions_)
      stable_dt_ = std::min(stable_dt_, in->stable_dt(nodes_));
    restore(carried);
  }

  void
  Contact::gather(const mesh::Discretization &discretization, const materials::MaterialLibrary &materials,
                  const particles::ParticleSet &particles, const std::vector<bool> &converted_cells,
                  const mesh::Vector &mass, const std::vector<bool> &involved)
  {
    // This rank's contact nodes and segments.
    const auto &bodies = discretization.bodies();
    const auto &pt     = *discretization.partitioner();
    const auto &X      = discretization.reference_positions();
    std::map<unsigned long long, std::array<double, node_record>> mine; // by global DOF
    const auto bulk_of = [&](const unsigned int b) { return materials.get(bodies[b].material).elastic_moduli()[0]; };
    const auto add_node = [&](const types::global_dof_index g, const unsigned int b, const double h,
                              const bool is_particle, const Vec3 &support) {
      if (!pt.in_local_range(g))
        return;
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
            const Point<3>     x0 = face->vertex(0), x1 = face->vertex(1), x3 = face->vertex(3);
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
    const auto         all_nodes = Utilities::MPI::all_gather(comm_, flat);
    const unsigned int rank      = Utilities::MPI::this_mpi_process(comm_);
    nodes_ = ContactNodes();
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
            ContactNode   n;
            n.dof           = static_cast<unsigned long long>(a[0]);
            n.X             = Vec3{{a[1], a[2], a[3]}};
            n.mass          = a[4];
            n.radius        = a[5];
            n.bulk          = a[6];
            n.spacing       = a[7];
            n.body          = static_cast<unsigned int>(a[8]);
            n.particle      = a[9] > 0;
            n.support       = Vec3{{a[10], a[11], a[12]}};
            index_of[n.dof] = nodes_.size();
            nodes_.nodes.push_back(n);
          }
        counts_[r] = state_record * nodes_.size() - displs_[r];
      }
    owned_local_dof_.clear();
    for (const auto &[g, r] : mine)
      owned_local_dof_.push_back(pt.global_to_local(g));
    for (const auto &part : all_segments)
      for (std::size_t p = 0; p < part.size(); p += segment_record)
        {
          ContactSegment s;
          for (unsigned int v = 0; v < 4; ++v)
            s.node[v] = index_of.at(static_cast<unsigned long long>(part[p + v]));
          s.stiffness = part[p + 4];
          s.body      = static_cast<unsigned int>(part[p + 5]);
          nodes_.segments.push_back(s);
        }
    nodes_.state.assign(state_record * nodes_.size(), 0.);
  }

  Contact::Carried
  Contact::carry() const
  {
    Carried c;
    if (nodes_.nodes.empty() || interactions_.empty())
      return c;
    const std::size_t n = nodes_.size();
    c.dof.resize(n);
    for (std::size_t i = 0; i < n; ++i)
      c.dof[i] = nodes_.nodes[i].dof;
    c.force = force_;
    NodeNaming naming;
    naming.name = [&](const unsigned int i) { return nodes_.nodes[i].dof; };
    for (const auto &in : interactions_)
      {
        base::BinaryWriter w;
        in->write_state(w, nodes_, naming);
        c.interactions.push_back(w.str());
      }
    for (std::size_t k = 0; k < owned_local_dof_.size() && 3 * k < x_old_.size(); ++k)
      {
        c.owned_dof.push_back(nodes_.nodes[owned_begin_ + k].dof);
        c.x_old.insert(c.x_old.end(), &x_old_[3 * k], &x_old_[3 * k] + 3);
      }
    return c;
  }

  void
  Contact::read_interactions(const std::vector<std::string> &states, const std::vector<int> &where,
                             const NodeNaming &naming)
  {
    for (std::size_t s = 0; s < interactions_.size(); ++s)
      {
        base::BinaryReader in(states[s]);
        interactions_[s]->read_state(in, nodes_, where, naming);
      }
  }

  void
  Contact::restore(const Carried &c)
  {
    if (c.dof.empty() || c.interactions.size() != interactions_.size())
      return;
    std::unordered_map<unsigned long long, unsigned int> index_of;
    for (unsigned int i = 0; i < nodes_.size(); ++i)
      index_of.emplace(nodes_.nodes[i].dof, i);
    NodeNaming naming;
    naming.index = [&](const unsigned long long dof) {
      const auto it = index_of.find(dof);
      return it == index_of.end() ? -1 : static_cast<int>(it->second);
    };
    std::vector<int> where(c.dof.size());
    for (std::size_t k = 0; k < c.dof.size(); ++k)
      {
        where[k] = naming.index(c.dof[k]);
        if (where[k] >= 0)
          for (unsigned int d = 0; d < 3; ++d)
            force_[3 * where[k] + d] = c.force[3 * k + d];
      }
    read_interactions(c.interactions, where, naming);
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
            const auto it = x_of.find(nodes_.nodes[owned_begin_ + k].dof);
            if (it != x_of.end())
              std::copy(it->second, it->second + 3, &x_old_[3 * k]);
          }
      }
  }

  double
  Contact::memory_consumption() const
  {
    return sizeof(ContactNode) * nodes_.nodes.capacity() + sizeof(ContactSegment) * nodes_.segments.capacity() +
           sizeof(double) * (nodes_.state.capacity() + force_.capacity() + force_old_.capacity() + x_old_.capacity() +
                             reach_.capacity()) +
           sizeof(Vec3) * x_build_.capacity() + sizeof(int) * (counts_.capacity() + displs_.capacity()) +
           sizeof(unsigned int) * owned_local_dof_.capacity();
  }

  double
  Contact::exchange(const mesh::Vector &d, const mesh::Vector &v)
  {
    if (interactions_.empty())
      return 0.;
    std::vector<double> mine(state_record * owned_local_dof_.size());
    for (std::size_t k = 0; k < owned_local_dof_.size(); ++k)
      {
        const ContactNode &n = nodes_.nodes[owned_begin_ + k];
        for (unsigned int c = 0; c < 3; ++c)
          {
            mine[state_record * k + c]     = n.X[c] + d.local_element(owned_local_dof_[k] + c);
            mine[state_record * k + 3 + c] = v.local_element(owned_local_dof_[k] + c);
          }
      }
    MPI_Allgatherv(mine.data(), static_cast<int>(mine.size()), MPI_DOUBLE, nodes_.state.data(), counts_.data(),
                   displs_.data(), MPI_DOUBLE, comm_);
    return base::Traffic::to_all_others(sizeof(double) * mine.size(), comm_);
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
    const unsigned int n = nodes_.size();
    // Bonds broken and particles freed since the last step (what the bond filter sees).
    const BondNews news = bonds_.sync(particles_->broken_bonds(), particles_->free_particles());
    // Rebuild rule: the rebuild interval, or a node moved more than its reach since the last
    // build.
    bool rebuild = !built_ || step >= last_build_ + rebuild_interval_;
    for (unsigned int i = 0; i < n && !rebuild; ++i)
      {
        const Vec3 x = nodes_.position(i);
        const Vec3 dx{{x[0] - x_build_[i][0], x[1] - x_build_[i][1], x[2] - x_build_[i][2]}};
        rebuild = norm(dx) > reach_[i];
      }
    if (rebuild)
      build_candidates(step, dt);
    else
      // Bonds broke since the last step and the candidates were not rebuilt: their pairs join
      // the candidates.
      for (auto &in : interactions_)
        in->wake(news);

    force_old_.swap(force_);
    std::fill(force_.begin(), force_.end(), 0.);
    ForceSink sink(force_, friction_velocity_);
    for (auto &in : interactions_)
      in->add_forces(nodes_, step, dt, sink);
    wall_force_ = sink.wall_force;

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
            const double x = nodes_.state[state_record * i + c];
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
        friction_energy_ += rounded_product(sink.friction_power, dt);
        damping_energy_ += rounded_product(sink.damping_power, dt);
        stored_energy_ = sink.stored;
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
    bonds_.save(out);
    out.put(static_cast<std::uint64_t>(interactions_.size()));
    for (const auto &in : interactions_)
      in->save(out);
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
    bonds_.load(in);
    if (in.get<std::uint64_t>() != interactions_.size())
      throw std::runtime_error("the contact interactions of the checkpoint differ from this scene's");
    for (auto &interaction : interactions_)
      interaction->load(in);
    in.get(last_build_);
    in.get(built_);
    in.get(n_rebuilds_);
    in.get(energy_);
    in.get(friction_energy_);
    in.get(damping_energy_);
    in.get(wall_force_);
  }

  Contact::PortableState
  Contact::portable_state(const std::function<unsigned long long(unsigned long long)> &key_of_node) const
  {
    PortableState p;
    for (const auto &n : nodes_.nodes)
      p.keys.push_back(key_of_node(n.dof / 3));
    p.force = force_;
    NodeNaming naming;
    naming.name = [&](const unsigned int i) { return p.keys[i]; };
    for (const auto &in : interactions_)
      {
        base::BinaryWriter w;
        in->write_state(w, nodes_, naming);
        p.interactions.push_back(w.str());
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
      index_of_dof.emplace(nodes_.nodes[i].dof, i);
    NodeNaming naming;
    naming.index = [&](const unsigned long long key) {
      const auto it = index_of_dof.find(3 * node_of_key(key));
      if (it == index_of_dof.end())
        throw std::runtime_error("contact node " + std::to_string(key) + " of the checkpoint is not a contact node");
      return static_cast<int>(it->second);
    };
    const auto &first = states.front();
    if (first.keys.size() != nodes_.size() || first.interactions.size() != interactions_.size())
      throw std::runtime_error("the contact nodes of the checkpoint differ from this scene's");
    std::vector<int> where(first.keys.size());
    for (std::size_t k = 0; k < first.keys.size(); ++k)
      {
        where[k] = naming.index(first.keys[k]);
        for (unsigned int c = 0; c < 3; ++c)
          force_[3 * where[k] + c] = first.force[3 * k + c];
      }
    read_interactions(first.interactions, where, naming);
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
        const auto it = x_of_key.find(key_of_node.at(nodes_.nodes[owned_begin_ + k].dof / 3));
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
  }
} // namespace shard::contact
