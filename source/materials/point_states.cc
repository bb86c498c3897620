// SPDX-License-Identifier: LGPL-2.1-or-later
#include <shard/materials/point_states.h>

#include <algorithm>

namespace shard::materials
{
  void
  PointStates::build(const std::vector<const Material *> &materials, const std::vector<unsigned int> &group_of,
                     const double *positions)
  {
    group_of_ = group_of;
    groups_.assign(materials.size(), Group());
    for (unsigned int g = 0; g < groups_.size(); ++g)
      {
        auto &grp    = groups_[g];
        grp.material = materials[g];
        grp.begin    = std::find(group_of_.begin(), group_of_.end(), g) - group_of_.begin();
        grp.end      = grp.begin + std::count(group_of_.begin(), group_of_.end(), g);
        grp.slot_names = grp.material->state_slot_names();
        grp.n_slots    = grp.slot_names.size();
        grp.state.assign(std::size_t(grp.end - grp.begin) * grp.n_slots, 0.);
        grp.material->initialize_state(grp.end - grp.begin, grp.state.data());
        if (grp.end > grp.begin)
          grp.material->set_position_fields(grp.end - grp.begin, positions + 3 * std::size_t(grp.begin),
                                            grp.state.data());
      }
    build_batches();
  }

  void
  PointStates::remove(const std::vector<bool> &drop)
  {
    unsigned int n = 0;
    for (auto &grp : groups_)
      {
        const unsigned int begin = n;
        for (unsigned int i = grp.begin; i < grp.end; ++i)
          if (!drop[i])
            {
              std::copy(&grp.state[std::size_t(i - grp.begin) * grp.n_slots],
                        &grp.state[std::size_t(i - grp.begin + 1) * grp.n_slots],
                        &grp.state[std::size_t(n - begin) * grp.n_slots]);
              group_of_[n] = group_of_[i];
              ++n;
            }
        grp.state.resize(std::size_t(n - begin) * grp.n_slots);
        grp.begin = begin;
        grp.end   = n;
      }
    group_of_.resize(n);
    build_batches();
  }

  double
  PointStates::state_value(const unsigned int i, const std::string &name) const
  {
    const auto &g  = groups_[group_of_[i]];
    const auto  it = std::find(g.slot_names.begin(), g.slot_names.end(), name);
    return it == g.slot_names.end() ? 0. : g.state[std::size_t(i - g.begin) * g.n_slots + (it - g.slot_names.begin())];
  }

  void
  PointStates::update(const Batch &b, const double dt, const double *de, const double *J, const double *length,
                      double *stress, double *c)
  {
    auto         &g = groups_[b.group];
    PointBatch    batch;
    batch.n                     = b.end - b.begin;
    batch.dt                    = dt;
    batch.strain_increment      = de;
    batch.relative_volume       = J;
    batch.characteristic_length = length;
    batch.stress                = stress + 6 * std::size_t(b.begin);
    batch.state                 = g.state.data() + std::size_t(b.begin - g.begin) * g.n_slots;
    batch.wave_speed            = c;
    g.material->update(batch);
  }

  std::size_t
  PointStates::memory_consumption() const
  {
    std::size_t bytes = group_of_.capacity() * sizeof(unsigned int) + batches_.capacity() * sizeof(Batch) +
                        groups_.capacity() * sizeof(Group);
    for (const auto &g : groups_)
      {
        bytes += g.state.capacity() * sizeof(double) + g.slot_names.capacity() * sizeof(std::string);
        for (const auto &n : g.slot_names)
          bytes += n.capacity() > 15 ? n.capacity() + 1 : 0; // heap part beyond the small-string buffer
      }
    return bytes;
  }

  void
  PointStates::build_batches()
  {
    // Batches of point_batch_size points within each group, in point order. Rigid materials get
    // none: no stress, no step limit (time::RigidBodies moves their nodes).
    batches_.clear();
    for (unsigned int g = 0; g < groups_.size(); ++g)
      if (!groups_[g].material->rigid())
        for (unsigned int b0 = groups_[g].begin; b0 < groups_[g].end; b0 += point_batch_size)
          batches_.push_back({g, b0, std::min(b0 + point_batch_size, groups_[g].end)});
  }
} // namespace shard::materials
