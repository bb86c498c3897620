// SPDX-License-Identifier: LGPL-2.1-or-later
// Checkpoint and restart of a Simulation (doc/manual/checkpoint.md): what a checkpoint holds,
// how every rank writes its share keyed by partition-independent ids, and how a restart at the
// same or another rank count reads it back. The energy balance and contact serialize
// themselves (EnergyBalance::serialize_global / rank_values, Contact::save / portable_state).
#include <shard/base/binary_archive.h>
#include <shard/base/sections.h>
#include <shard/simulation/simulation.h>

#include <deal.II/base/mpi.h>

#include <cstdio>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <stdexcept>

namespace shard
{
  using namespace dealii;

  namespace
  {
    /// The first @p bytes bytes of the file @p path (fewer if it is shorter; "" if absent).
    std::string
    file_head(const std::string &path, const unsigned long long bytes)
    {
      std::ifstream in(path, std::ios::binary);
      std::string   data(bytes, '\0');
      in.read(data.data(), static_cast<std::streamsize>(bytes));
      data.resize(in ? bytes : static_cast<std::size_t>(std::max<std::streamsize>(in.gcount(), 0)));
      return data;
    }
  } // namespace

  namespace
  {
    using Bond = particles::ParticleSet::Bond;
    using Keys = std::vector<unsigned long long>;

    /// The part of a checkpoint that is the same on every rank (read from rank 0's file).
    struct SavedGlobal
    {
      unsigned int                                               step = 0;
      double                                                     t = 0, dt = 0, dt_next = 0, stable_dt = 0;
      double                                                     first_stable_dt = 0;
      double                                                     initial_max_speed = 0, next_output = 0;
      double                                                     held_dt = 0, last_fragments_time = -1;
      std::vector<double>                                        q_final, q_min, q_max;
      std::array<std::vector<std::pair<double, std::string>>, 2> records;
      unsigned char                                              fragments_started = 0;
      unsigned long long                                         history_bytes = 0, fragments_bytes = 0;
      std::uint64_t                                              history_hash = 0, fragments_hash = 0;
      std::vector<unsigned int>                                  converted;
      unsigned int                                               n_events = 0, n_rebuilds = 0;
      unsigned long long                                         n_broken = 0, n_free = 0;
    };

    /// One rank's share: its scalars and its owned nodes, elements and particles.
    struct SavedRank
    {
      Keys                      ghosts;
      std::vector<double>       energy;   // EnergyBalance::rank_values()
      std::vector<double>       counters; // element steps, particle steps, particle step
      double                    contact_energy = 0, friction_energy = 0;
      /// Owned nodes (StepState), elements (HexForce) and particles (SpgForce), by key.
      base::KeyedRecords        nodes, elements, particles;
      unsigned char             has_contact = 0;
      std::vector<unsigned int> changed_rows; // ParticleSet::changed_rows(), local rows
      /// The broken bonds and free particles this rank knows of, by node key (at the last
      /// prepare and now); their union over the ranks is every one.
      std::vector<std::pair<unsigned long long, unsigned long long>> bonds_at_prepare, bonds;
      Keys                                                           free_at_prepare, free;
    };

    /// The bonds of a checkpoint (pairs of node keys) with an end this rank owns, as particle
    /// ids (first < second).
    std::vector<Bond>
    owned_bonds(const output::Checkpoint &checkpoint, const Utilities::MPI::Partitioner &pt,
                const std::vector<std::pair<unsigned long long, unsigned long long>> &keys)
    {
      std::vector<Bond> out;
      for (const auto &[ka, kb] : keys)
        {
          const unsigned long long a = checkpoint.node_of_key(ka), b = checkpoint.node_of_key(kb);
          if (pt.in_local_range(3 * a) || pt.in_local_range(3 * b))
            out.emplace_back(std::min(a, b), std::max(a, b));
        }
      return out;
    }

    /// The particles of a checkpoint (node keys) this rank owns, as particle ids.
    Keys
    owned_nodes(const output::Checkpoint &checkpoint, const Utilities::MPI::Partitioner &pt, const Keys &keys)
    {
      Keys out;
      for (const auto k : keys)
        if (const unsigned long long id = checkpoint.node_of_key(k); pt.in_local_range(3 * id))
          out.push_back(id);
      return out;
    }

    /// One list of fields for writing and reading (@p io is put or get).
    template <typename IO>
    void
    serialize(IO &&io, SavedGlobal &g)
    {
      io(g.step), io(g.t), io(g.dt), io(g.dt_next), io(g.stable_dt);
      io(g.first_stable_dt), io(g.initial_max_speed), io(g.next_output), io(g.held_dt);
      io(g.last_fragments_time), io(g.q_final), io(g.q_min), io(g.q_max), io(g.records);
      io(g.fragments_started), io(g.history_bytes), io(g.fragments_bytes), io(g.history_hash);
      io(g.fragments_hash), io(g.converted), io(g.n_events);
      io(g.n_rebuilds), io(g.n_broken), io(g.n_free);
    }

    template <typename IO>
    void
    serialize(IO &&io, SavedRank &r)
    {
      io(r.ghosts), io(r.energy), io(r.counters), io(r.contact_energy), io(r.friction_energy);
      r.nodes.serialize(io), r.elements.serialize(io), r.particles.serialize(io);
      io(r.has_contact), io(r.changed_rows);
      io(r.bonds_at_prepare), io(r.bonds), io(r.free_at_prepare), io(r.free);
    }

    /// Reads header, global part, energy balance and rank part of one payload; @p reader stays after them.
    void
    read_payload(base::BinaryReader &reader, SavedGlobal &g, EnergyBalance &energy, SavedRank &r)
    {
      reader.expect("shard state");
      reader.get<unsigned int>();
      reader.get<unsigned int>();
      reader.expect("global");
      serialize([&](auto &x) { reader.get(x); }, g);
      reader.expect("energy");
      energy.serialize_global([&](auto &x) { reader.get(x); });
      reader.expect("rank");
      serialize([&](auto &x) { reader.get(x); }, r);
    }

    /// Restart: d, v, v_now, f, f_ext of the owned nodes, element and particle state by key,
    /// from whichever rank of the checkpoint wrote them; each component reads its own records.
    void
    restore_owned_values(const std::vector<SavedRank> &ranks, const output::Checkpoint &checkpoint_,
                         fe::HexForce &hex_, particles::SpgForce &spg_, const particles::ParticleSet &particles_,
                         StepState &state_)
    {
      std::vector<const base::KeyedRecords *> nodes, elements, particles;
      for (const auto &r : ranks)
        {
          nodes.push_back(&r.nodes);
          elements.push_back(&r.elements);
          particles.push_back(&r.particles);
        }
      state_.restore_portable(base::KeyedLookup(nodes),
                              [&](const unsigned int j) { return checkpoint_.key_of_local_dof(j); });
      hex_.restore_portable(base::KeyedLookup(elements));
      spg_.restore_portable(base::KeyedLookup(particles), [&](const unsigned int i) {
        return checkpoint_.key_of_local_dof(particles_.local_dof(i));
      });
    }
  } // namespace

  std::string
  Simulation::fingerprint() const
  {
    // The parameters as read, without the keys a restart may change.
    std::ostringstream all;
    prm_.print_parameters(all, ParameterHandler::ShortPRM | ParameterHandler::KeepDeclarationOrder);
    std::istringstream in(all.str());
    std::ostringstream out;
    std::string        line, top;
    int                depth = 0;
    while (std::getline(in, line))
      {
        const auto first = line.find_first_not_of(' ');
        if (first == std::string::npos)
          continue;
        const std::string l = line.substr(first);
        if (l.rfind("subsection ", 0) == 0)
          {
            if (depth++ == 0)
              top = l.substr(11);
            continue;
          }
        if (l == "end")
          {
            --depth;
            continue;
          }
        if (top == sections::output || top == sections::checkpoint || l.rfind("set end time", 0) == 0 ||
            l.rfind("set max steps", 0) == 0 || l.rfind("set title", 0) == 0)
          continue;
        out << top << ": " << l << "\n";
      }
    out << "dofs " << discretization_.dof_handler().n_dofs() << " cells " << discretization_.n_elements() << "\n";
    return out.str();
  }

  void
  Simulation::write_checkpoint()
  {
    checkpoint_.share_node_keys();
    const unsigned int rank = Utilities::MPI::this_mpi_process(comm_);
    const auto        &pt   = *discretization_.partitioner();
    const auto key_bonds = [&](const std::vector<Bond> &bonds) {
      std::vector<std::pair<unsigned long long, unsigned long long>> out;
      for (const auto &[a, b] : bonds)
        out.emplace_back(checkpoint_.key_of_node(a), checkpoint_.key_of_node(b));
      return out;
    };
    const auto key_nodes = [&](const Keys &ids) {
      Keys out;
      for (const auto id : ids)
        out.push_back(checkpoint_.key_of_node(id));
      return out;
    };

    SavedGlobal g;
    g.step = state_.step, g.t = state_.t, g.dt = state_.dt, g.dt_next = state_.dt_next, g.stable_dt = state_.stable_dt;
    g.first_stable_dt = state_.first_stable_dt, g.initial_max_speed = initial_max_speed_, g.next_output = next_output_;
    g.held_dt = integrator_.held_dt(), g.last_fragments_time = last_fragments_time_;
    g.q_final = q_final_, g.q_min = q_min_, g.q_max = q_max_, g.records = output_.records();
    g.fragments_started = fragments_started_;
    if (rank == 0)
      {
        history_.flush();
        const std::string fragments = output_.directory() + "/fragments.csv";
        g.history_bytes             = std::filesystem::file_size(output_.directory() + "/history.csv");
        g.fragments_bytes = std::filesystem::exists(fragments) ? std::filesystem::file_size(fragments) : 0;
        // The content, so that a restart continues these very tables (not only as long ones).
        g.history_hash   = base::fnv1a(file_head(output_.directory() + "/history.csv", g.history_bytes));
        g.fragments_hash = base::fnv1a(file_head(fragments, g.fragments_bytes));
      }
    // Each rank knows the converted cells it holds; its owned ones are written (the union over
    // the ranks is the converted set).
    for (const auto &cell : discretization_.triangulation().active_cell_iterators())
      if (cell->is_locally_owned() && conversion_.converted_cells()[cell->active_cell_index()])
        g.converted.push_back(static_cast<unsigned int>(cell->id().get_coarse_cell_id()));
    g.n_events = conversion_.n_events(), g.n_rebuilds = contact_.n_rebuilds();
    g.n_broken = bonds_.n_broken(), g.n_free = bonds_.n_free();

    SavedRank r;
    for (const auto i : pt.ghost_indices())
      r.ghosts.push_back(i);
    r.energy   = energy_.rank_values();
    r.counters = {explicit_step_.element_steps(), explicit_step_.particle_steps(), state_.particle_dt};
    r.contact_energy = contact_.energy(), r.friction_energy = contact_.friction_energy();
    r.nodes    = state_.portable_state([&](const unsigned int j) { return checkpoint_.key_of_local_dof(j); });
    r.elements = hex_.portable_state();
    if (spg_.active())
      r.particles = spg_.portable_state(
        [&](const unsigned int i) { return checkpoint_.key_of_local_dof(particles_.local_dof(i)); });
    r.has_contact = contact_.active();
    if (particles_.active())
      {
        r.changed_rows     = particles_.changed_rows();
        r.bonds_at_prepare = key_bonds(particles_.bonds_at_prepare());
        r.bonds            = key_bonds(particles_.broken_bonds());
        r.free_at_prepare  = key_nodes(particles_.free_at_prepare());
        r.free             = key_nodes(particles_.free_particles());
      }

    base::BinaryWriter w;
    w.put(std::string("shard state"));
    w.put(Utilities::MPI::n_mpi_processes(comm_));
    w.put(rank);
    w.put(std::string("global"));
    serialize([&](auto &x) { w.put(x); }, g);
    w.put(std::string("energy"));
    energy_.serialize_global([&](auto &x) { w.put(x); });
    w.put(std::string("rank"));
    serialize([&](auto &x) { w.put(x); }, r);
    if (r.has_contact)
      {
        // Exact at the same partition; portable (by node key) for another rank count.
        base::BinaryWriter exact;
        contact_.save(exact);
        w.put(exact.str());
        auto portable = contact_.portable_state([&](const unsigned long long n) { return checkpoint_.key_of_node(n); });
        portable.serialize([&](auto &x) { w.put(x); });
      }
    w.put(std::string("end"));
    checkpoint_.write(state_.step, state_.t, w.str());
  }

  void
  Simulation::restore_topology()
  {
    checkpoint_.share_node_keys();
    const std::string         key = sections::checkpoint + "/restart from";
    SavedGlobal               g;
    SavedRank                 r;
    std::vector<std::uint64_t> converted; // coarse cell ids
    // The broken bonds and free particles at the last prepare with an end this rank owns, from
    // every rank of the checkpoint (each part cut as it is read: no rank holds all of them).
    const auto       &pt = *discretization_.partitioner();
    std::vector<Bond> bonds_at_prepare;
    Keys              free_at_prepare;
    try
      {
        const unsigned int own = checkpoint_.same_rank_count() ? Utilities::MPI::this_mpi_process(comm_) : 0;
        for (unsigned int q = 0; q < checkpoint_.restart_ranks(); ++q)
          {
            base::BinaryReader reader(checkpoint_.payload(q));
            SavedGlobal        gq;
            SavedRank          rq;
            EnergyBalance      energy; // read past (restore_state() takes it)
            read_payload(reader, gq, energy, rq);
            converted.insert(converted.end(), gq.converted.begin(), gq.converted.end());
            for (const auto &b : owned_bonds(checkpoint_, pt, rq.bonds_at_prepare))
              bonds_at_prepare.push_back(b);
            for (const auto id : owned_nodes(checkpoint_, pt, rq.free_at_prepare))
              free_at_prepare.push_back(id);
            if (q == 0)
              g = std::move(gq);
            if (q == own)
              r = std::move(rq);
          }
        std::sort(converted.begin(), converted.end());
        converted.erase(std::unique(converted.begin(), converted.end()), converted.end());
      }
    catch (const std::exception &e)
      {
        source_.fail(key, checkpoint_.restart_manifest(), std::string("cannot read the checkpoint: ") + e.what());
      }

    for (const auto c : converted)
      if (c >= discretization_.n_elements())
        source_.fail(key, checkpoint_.restart_manifest(), "the checkpoint names a cell this mesh does not have.");
    conversion_.restore(converted, g.n_events);
    particles_.restore_broken(std::move(bonds_at_prepare), std::move(free_at_prepare));
    // Rows rebuilt for broken bonds use the failure condition limit, which the run had set
    // (BondFailure::prepare) before every rebuild of the particle set after the first.
    particles_.set_broken_condition_limit(bonds_.condition_limit());
    // The same ghost set as the run that wrote the checkpoint (it only grows at conversions),
    // so that local indices and the order of every sum are the same.
    if (checkpoint_.same_rank_count())
      {
        IndexSet ghosts(discretization_.dof_handler().n_dofs());
        ghosts.add_indices(r.ghosts.begin(), r.ghosts.end());
        discretization_.add_ghost_dofs(ghosts);
      }
  }

  void
  Simulation::restore_state()
  {
    checkpoint_.share_node_keys();
    const std::string  key  = sections::checkpoint + "/restart from";
    const unsigned int rank = Utilities::MPI::this_mpi_process(comm_);
    const bool         same = checkpoint_.same_rank_count();
    std::string        error;
    try
      {
        SavedGlobal                                 g;
        std::vector<SavedRank>                      ranks(checkpoint_.restart_ranks());
        std::vector<contact::Contact::PortableState> contact_states;
        for (unsigned int q = 0; q < ranks.size(); ++q)
          {
            base::BinaryReader reader(checkpoint_.payload(q));
            SavedGlobal        gq;
            EnergyBalance      energy;
            read_payload(reader, q == 0 ? g : gq, q == 0 ? energy_ : energy, ranks[q]);
            if (ranks[q].has_contact != contact_.active())
              throw std::runtime_error("contact is on in one of the checkpoint and this scene, off in the other");
            if (ranks[q].has_contact)
              {
                std::string exact;
                reader.get(exact);
                if (same && q == rank)
                  {
                    base::BinaryReader in(exact);
                    contact_.load(in);
                  }
                contact_states.emplace_back();
                contact_states.back().serialize([&](auto &x) { reader.get(x); });
              }
            reader.expect("end");
          }

        // Topology after the last rebuild: the bonds that broke since then. Each rank takes
        // those of its own particles from all ranks' lists and tells the ranks that hold them.
        if (particles_.active())
          {
            const auto       &pt = *discretization_.partitioner();
            std::vector<Bond> bonds;
            Keys              free;
            for (const auto &rq : ranks)
              {
                for (const auto &b : owned_bonds(checkpoint_, pt, rq.bonds))
                  bonds.push_back(b);
                for (const auto id : owned_nodes(checkpoint_, pt, rq.free))
                  free.push_back(id);
              }
            particles_.break_bonds(bonds, free);
            particles_.restrict_to_needed(comm_);
            particles_.take_rebuilt_rows();
            // The rows whose bond count the next breaking step looks at: as in the run at the
            // same partition; at another, every row (as after a rebuild of the particle set).
            if (same)
              particles_.restore_changed_rows(ranks[rank].changed_rows);
            bonds_.prepare(particles_, spg_, source_);
            fragments_stale_ = true;
          }
        bonds_.restore_counts(g.n_broken, g.n_free);

        restore_owned_values(ranks, checkpoint_, hex_, spg_, particles_, state_);
        state_.d.update_ghost_values();
        state_.v.update_ghost_values();
        state_.v_now.update_ghost_values();
        const double stabilization = spg_.reset_deformation(state_.d);

        // Energy accounts and counters: this rank's own at the same rank count; at another the
        // sums on rank 0 (the particle step: the smallest).
        std::vector<double> energy   = ranks[0].energy;
        std::vector<double> counters = ranks[0].counters;
        double              contact_energy = ranks[0].contact_energy;
        if (counters.size() != 3)
          throw std::runtime_error("wrong number of counters");
        if (same)
          energy = ranks[rank].energy, counters = ranks[rank].counters;
        else
          {
            for (unsigned int q = 1; q < ranks.size(); ++q)
              {
                for (unsigned int k = 0; k < energy.size() && k < ranks[q].energy.size(); ++k)
                  energy[k] += ranks[q].energy[k];
                counters[0] += ranks[q].counters.at(0), counters[1] += ranks[q].counters.at(1);
                counters[2] = std::min(counters[2], ranks[q].counters.at(2));
                contact_energy += ranks[q].contact_energy;
              }
            if (rank != 0)
              {
                std::fill(energy.begin(), energy.end(), 0.);
                counters[0] = counters[1] = 0;
                contact_energy            = 0;
              }
            if (contact_.active())
              contact_.restore_portable(
                contact_states, [&](const unsigned long long key) { return checkpoint_.node_of_key(key); },
                contact_energy);
          }
        energy_.restore_rank_values(energy, same, stabilization);
        explicit_step_.restore_counters(counters[0], counters[1]);
        state_.particle_dt = counters[2];

        state_.step = g.step, state_.t = g.t, state_.dt = g.dt, state_.dt_next = g.dt_next, state_.stable_dt = g.stable_dt;
        state_.first_stable_dt = g.first_stable_dt, initial_max_speed_ = g.initial_max_speed;
        next_output_ = g.next_output, last_fragments_time_ = g.last_fragments_time;
        // 'K - Output/interval' may change on restart: a smaller interval than the checkpointed
        // run's (or one set where that run had 0) takes effect from here. With the same interval
        // this is a no-op: the checkpointed next output lies within one interval of t.
        if (output_.interval() > 0)
          next_output_ = std::min(next_output_, state_.t + output_.interval());
        integrator_.set_held_dt(g.held_dt);
        q_final_ = g.q_final, q_min_ = g.q_min, q_max_ = g.q_max;
        output_.restore_records(g.records);
        fragments_started_ = g.fragments_started;
        history_bytes_ = g.history_bytes, fragments_bytes_ = g.fragments_bytes;
        history_hash_ = g.history_hash, fragments_hash_ = g.fragments_hash;
        if (rank == 0)
          truncate_tables();
      }
    catch (const std::exception &e)
      {
        error = e.what();
      }
    // Every rank fails together, with the first message.
    for (const auto &m : Utilities::MPI::all_gather(comm_, error))
      if (!m.empty())
        source_.fail(key, checkpoint_.restart_manifest(), "cannot restart from the checkpoint: " + m);
    if (rank == 0)
      std::fprintf(stderr, "shard: restart from %s: step %u, t = %.6e s (written at %u ranks)\n",
                   checkpoint_.restart_manifest().c_str(), state_.step, state_.t, checkpoint_.restart_ranks());
    checkpoint_.release();
  }

  void
  Simulation::truncate_tables() const
  {
    for (const auto &[name, bytes, hash] : {std::make_tuple(std::string("history.csv"), history_bytes_, history_hash_),
                                            std::make_tuple(std::string("fragments.csv"), fragments_bytes_, fragments_hash_)})
      {
        const std::string path = output_.directory() + "/" + name;
        if (!std::filesystem::exists(path))
          {
            if (bytes > 0)
              throw base::InputError(sections::checkpoint + "/restart from: " + path +
                                     " is missing; a restart continues the tables of the run that wrote the "
                                     "checkpoint (same K - Output/directory).");
            continue;
          }
        if (std::filesystem::file_size(path) < bytes)
          throw base::InputError(sections::checkpoint + "/restart from: " + path + " is shorter than at the checkpoint (" +
                                 std::to_string(bytes) + " bytes); it does not belong to this run.");
        if (base::fnv1a(file_head(path, bytes)) != hash)
          throw base::InputError(sections::checkpoint + "/restart from: the first " + std::to_string(bytes) + " bytes of " + path +
                                 " differ from those at the checkpoint (FNV-1a hash); it was changed since, or "
                                 "belongs to another run.");
        std::filesystem::resize_file(path, bytes);
      }
  }
} // namespace shard
