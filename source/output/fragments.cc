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
    discretization_ = &discretization;
    edges_.clear();
    // An intact element connects its eight nodes (a star through its first node suffices).
    for (unsigned int e = 0; e < hex.n_local_elements(); ++e)
      for (unsigned int a = 1; a < 8; ++a)
        edges_.emplace_back(hex.node(e, 0), hex.node(e, a));
    // A particle row connects the particle to the particles of its stencil (its bonds).
    const auto &g = particles.stencils().g;
    for (unsigned int i = 0; i < particles.n_owned(); ++i)
      for (unsigned int k = g.row_offsets[i]; k < g.row_offsets[i + 1]; ++k)
        if (g.columns[k] != i)
          edges_.emplace_back(particles.local_dof(i), particles.local_dof(g.columns[k]));
    particle_.assign(discretization.partitioner()->locally_owned_size() / 3, 0);
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
      label.local_element(j) = static_cast<double>(pt.local_to_global(j) / 3);
    // Min-propagation: every edge takes the smaller label of its ends, owners combine the
    // ghost entries by min, until no owned label changes on any rank.
    for (bool changed = true; changed;)
      {
        label.update_ghost_values();
        std::vector<double> before(label.begin(), label.begin() + n);
        for (bool local_change = true; local_change;)
          {
            local_change = false;
            for (const auto &[a, b] : edges_)
              {
                double &la = label.local_element(a), &lb = label.local_element(b);
                if (la != lb)
                  {
                    la = lb = std::min(la, lb);
                    local_change = true;
                  }
              }
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
