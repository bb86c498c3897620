// SPDX-License-Identifier: LGPL-2.1-or-later
#include <shard/output/fragments.h>

#include <deal.II/base/mpi.h>

#include <algorithm>
#include <map>

namespace shard::output
{
  using namespace dealii;

  void
  Fragments::prepare(const mesh::Discretization &discretization, const fe::HexForce &hex,
                     const particles::ParticleSet &particles)
  {
    discretization_    = &discretization;
    const auto     &pt = *discretization.partitioner();
    const unsigned int n_nodes = (pt.locally_owned_size() + pt.n_ghost_indices()) / 3;
    std::vector<unsigned int> parent(n_nodes);
    for (unsigned int k = 0; k < n_nodes; ++k)
      parent[k] = k;
    const auto root = [&](unsigned int k) {
      while (parent[k] != k)
        k = parent[k] = parent[parent[k]];
      return k;
    };
    const auto join = [&](const unsigned int a, const unsigned int b) {
      const unsigned int ra = root(a / 3), rb = root(b / 3);
      if (ra != rb)
        parent[std::max(ra, rb)] = std::min(ra, rb);
    };
    // An intact element connects its eight nodes.
    for (unsigned int e = 0; e < hex.n_local_elements(); ++e)
      for (unsigned int a = 1; a < 8; ++a)
        join(hex.node(e, 0), hex.node(e, a));
    // A particle row connects the particle to the particles of its stencil (its bonds).
    const auto &g = particles.stencils().g;
    for (unsigned int i = 0; i < particles.n_owned(); ++i)
      for (unsigned int k = g.row_offsets[i]; k < g.row_offsets[i + 1]; ++k)
        if (particles.g_entry_intact(k))
          join(particles.local_dof(i), particles.local_dof(g.columns[k]));
    // Members grouped by root (counting sort).
    std::vector<unsigned int> component(n_nodes), count;
    std::vector<int>          index_of_root(n_nodes, -1);
    for (unsigned int k = 0; k < n_nodes; ++k)
      {
        const unsigned int r = root(k);
        if (index_of_root[r] < 0)
          {
            index_of_root[r] = static_cast<int>(count.size());
            count.push_back(0);
          }
        component[k] = index_of_root[r];
        ++count[component[k]];
      }
    offsets_.assign(count.size() + 1, 0);
    for (std::size_t c = 0; c < count.size(); ++c)
      offsets_[c + 1] = offsets_[c] + count[c];
    members_.resize(n_nodes);
    std::vector<unsigned int> next(offsets_.begin(), offsets_.end() - 1);
    for (unsigned int k = 0; k < n_nodes; ++k)
      members_[next[component[k]]++] = 3 * k;
    // Fragment ids: the coarse-mesh vertex index, the same at any number of ranks (every cell
    // is a coarse cell, and the coarse mesh is the same on every rank), unlike DoF numbers.
    node_id_.assign(pt.locally_owned_size() / 3, 0);
    for (const auto &cell : discretization.dof_handler().active_cell_iterators())
      if (cell->is_locally_owned())
        for (const unsigned int v : cell->vertex_indices())
          {
            const auto g = cell->vertex_dof_index(v, 0);
            if (pt.in_local_range(g))
              node_id_[pt.global_to_local(g) / 3] = cell->vertex_index(v);
          }
    particle_.assign(pt.locally_owned_size() / 3, 0);
    for (unsigned int i = 0; i < particles.n_owned(); ++i)
      particle_[particles.local_dof(i) / 3] = 1;
  }

  std::vector<Fragment>
  Fragments::compute(const mesh::Vector &d, const mesh::Vector &v, const mesh::Vector &mass) const
  {
    const auto        &pt   = *discretization_->partitioner();
    const auto         comm = discretization_->communicator();
    const unsigned int n    = pt.locally_owned_size();
    mesh::Vector       label;
    discretization_->initialize_vector(label);
    for (unsigned int j = 0; j < n; j += 3)
      label.local_element(j) = static_cast<double>(node_id_[j / 3]);
    // Every local component takes the smallest label of its nodes, the owners combine the
    // ghost entries by min, until no owned label changes on any rank.
    for (bool changed = true; changed;)
      {
        label.update_ghost_values();
        std::vector<double> before(label.begin(), label.begin() + n);
        for (std::size_t c = 0; c + 1 < offsets_.size(); ++c)
          {
            double smallest = label.local_element(members_[offsets_[c]]);
            for (unsigned int k = offsets_[c] + 1; k < offsets_[c + 1]; ++k)
              smallest = std::min(smallest, label.local_element(members_[k]));
            for (unsigned int k = offsets_[c]; k < offsets_[c + 1]; ++k)
              label.local_element(members_[k]) = smallest;
          }
        label.compress(VectorOperation::min);
        bool mine = false;
        for (unsigned int j = 0; j < n; j += 3)
          mine |= label.local_element(j) != before[j];
        changed = Utilities::MPI::logical_or(mine, comm);
      }

    // Sums per label on this rank, then over ranks (rank order), sorted by label.
    const auto &X = discretization_->reference_positions();
    std::map<unsigned long long, std::array<double, 10>> local; // nodes, particles, m, m x (3), m v (3), ke
    for (unsigned int j = 0; j < n; j += 3)
      {
        auto &s = local[static_cast<unsigned long long>(label.local_element(j))];
        s[0] += 1;
        s[1] += particle_[j / 3];
        const double m = mass.local_element(j);
        s[2] += m;
        for (unsigned int c = 0; c < 3; ++c)
          {
            s[3 + c] += m * (X.local_element(j + c) + d.local_element(j + c));
            s[6 + c] += m * v.local_element(j + c);
            s[9] += 0.5 * m * v.local_element(j + c) * v.local_element(j + c);
          }
      }
    std::vector<double> flat;
    for (const auto &[id, s] : local)
      {
        flat.push_back(static_cast<double>(id));
        flat.insert(flat.end(), s.begin(), s.end());
      }
    std::map<unsigned long long, std::array<double, 10>> total;
    for (const auto &part : Utilities::MPI::all_gather(comm, flat))
      for (std::size_t k = 0; k < part.size(); k += 11)
        {
          auto &s = total[static_cast<unsigned long long>(part[k])];
          for (unsigned int c = 0; c < 10; ++c)
            s[c] += part[k + 1 + c];
        }
    std::vector<Fragment> out;
    for (const auto &[id, s] : total)
      {
        Fragment f;
        f.id        = id;
        f.nodes     = static_cast<unsigned long long>(s[0]);
        f.particles = static_cast<unsigned long long>(s[1]);
        f.mass      = s[2];
        for (unsigned int c = 0; c < 3; ++c)
          {
            f.centre[c]   = s[2] > 0 ? s[3 + c] / s[2] : 0.;
            f.velocity[c] = s[2] > 0 ? s[6 + c] / s[2] : 0.;
          }
        f.kinetic_energy = s[9];
        out.push_back(f);
      }
    return out;
  }
} // namespace shard::output
