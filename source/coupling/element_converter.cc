// SPDX-License-Identifier: LGPL-2.1-or-later
#include <shard/coupling/element_converter.h>
#include <shard/fe/hex_kernel.h>

#include <deal.II/base/mpi.h>

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <string>

namespace shard::coupling
{
  using namespace dealii;

  namespace
  {
    /// Moves the owned values of @p v to the layout of @p partitioner (ghosts zero).
    void
    move_to_layout(mesh::Vector &v, const std::shared_ptr<const Utilities::MPI::Partitioner> &partitioner)
    {
      if (v.get_partitioner() == partitioner)
        return;
      std::vector<double> owned(v.begin(), v.end());
      v.reinit(partitioner);
      std::copy(owned.begin(), owned.end(), v.begin());
    }
  } // namespace

  ElementConverter::Result
  ElementConverter::convert(const std::vector<unsigned int> &elements, const std::vector<mesh::Vector *> &vectors,
                            mesh::Vector &d, mesh::Vector &v)
  {
    auto          &hex  = c_.hex;
    auto          &spg  = c_.spg;
    auto          &particles = c_.particles;
    const MPI_Comm comm = c_.discretization.communicator();
    Result         result;

    std::vector<unsigned int> cells;
    for (const unsigned int e : elements)
      cells.push_back(hex.cell_index(e));
    result.added = c_.conversion.add_cells(cells);
    if (result.added == 0)
      return result;

    // 1. Volume-weighted history of the converted elements at their nodes: weight V_e / 8, then
    // the six stresses and the history slots, packed three per node into distributed vectors.
    unsigned int max_slots = 0;
    for (const unsigned int e : elements)
      max_slots = std::max(max_slots, hex.material(e).n_state_slots());
    max_slots                   = Utilities::MPI::max(max_slots, comm);
    const unsigned int n_values = 7 + max_slots;
    std::vector<mesh::Vector> acc((n_values + 2) / 3);
    for (auto &a : acc)
      c_.discretization.initialize_vector(a);
    double energy[2] = {0, 0}; // elastic energy before and after, this rank
    for (const unsigned int e : elements)
      {
        const auto         &m = hex.material(e);
        const double        w = hex.reference_volume(e) / 8;
        std::vector<double> values(n_values, 0.);
        values[0] = 1;
        std::copy(hex.stress(e), hex.stress(e) + 6, &values[1]);
        std::copy(hex.state(e), hex.state(e) + m.n_state_slots(), &values[7]);
        for (unsigned int a = 0; a < 8; ++a)
          for (unsigned int k = 0; k < n_values; ++k)
            acc[k / 3].local_element(hex.node(e, a) + k % 3) += w * values[k];
        double x[8][3], B[8][3];
        for (unsigned int a = 0; a < 8; ++a)
          for (unsigned int c = 0; c < 3; ++c)
            {
              const unsigned int j = hex.node(e, a) + c;
              x[a][c]              = c_.discretization.reference_positions().local_element(j) + d.local_element(j);
            }
        const double jacobian = fe::hex_volume_gradient(x, B) / hex.reference_volume(e);
        energy[0] += m.elastic_energy_density(hex.stress(e), jacobian) * hex.reference_volume(e);
      }
    for (auto &a : acc)
      a.compress(VectorOperation::add);
    const auto saved = spg.save_state();

    // 2. New particle set, stencils and ghost set; vectors and element nodes follow the layout.
    hex.remove_elements(elements);
    const auto old_partitioner = c_.discretization.partitioner();
    particles.prepare(c_.discretization, c_.conversion.converted_cells(), c_.conditions.faces(), c_.source);
    const auto &partitioner = c_.discretization.partitioner();
    if (partitioner != old_partitioner)
      {
        hex.relocalize(*old_partitioner, *partitioner);
        for (auto *vec : vectors)
          move_to_layout(*vec, partitioner);
        for (auto &a : acc)
          move_to_layout(a, partitioner);
      }
    spg.prepare(c_.discretization, particles, c_.materials);
    c_.bonds.prepare(particles, spg, c_.source);

    // 3. History of every owned particle: kept, or the volume average of what it had and what
    // its newly converted cells bring, h = (V_old h_old + sum V_e/8 h_e) / V_new.
    std::vector<double>       mixed(n_values);
    std::vector<unsigned int> received;
    for (unsigned int i = 0; i < spg.n_owned(); ++i)
      {
        const unsigned int j  = particles.local_dof(i);
        const auto         it = saved.find(particles.global_id(i));
        const auto        &m  = spg.material(i);
        const double       w  = acc[0].local_element(j);
        if (w == 0)
          {
            if (it != saved.end())
              spg.set_state(i, it->second.stress.data(), it->second.state.data(), it->second.q);
            continue;
          }
        const double v_old = it != saved.end() ? it->second.volume : 0.;
        const double v_new = v_old + w;
        if (std::abs(v_new - particles.volume(i)) > 1e-9 * v_new)
          throw std::logic_error("conversion: particle volume " + std::to_string(particles.volume(i)) +
                                 " differs from the transferred " + std::to_string(v_new));
        for (unsigned int k = 1; k < n_values; ++k)
          mixed[k] = acc[k / 3].local_element(j + k % 3);
        if (it != saved.end())
          {
            for (unsigned int c = 0; c < 6; ++c)
              mixed[1 + c] += v_old * it->second.stress[c];
            for (unsigned int k = 0; k < it->second.state.size(); ++k)
              mixed[7 + k] += v_old * it->second.state[k];
            energy[0] += m.elastic_energy_density(it->second.stress.data(), it->second.jacobian) * v_old;
          }
        for (unsigned int k = 1; k < n_values; ++k)
          mixed[k] /= v_new;
        spg.set_state(i, &mixed[1], &mixed[7], it != saved.end() ? it->second.q : 0.);
        received.push_back(i);
      }

    // 4. Kinematics of the new stencils from the current coefficients, then the energy after.
    d.update_ghost_values();
    v.update_ghost_values();
    spg.keep_residuals(d, saved);
    result.stabilization = spg.reset_deformation(d);
    // The particles that existed keep their relative volume J = c det F across the new
    // stencils (SpgForce::volume_factor); new particles start at c = 1.
    for (unsigned int i = 0; i < spg.n_owned(); ++i)
      {
        const auto   it = saved.find(particles.global_id(i));
        const double j  = spg.jacobian(i);
        if (it != saved.end() && j > 0)
          spg.set_volume_factor(i, it->second.jacobian / j);
      }
    for (const unsigned int i : received)
      energy[1] += spg.material(i).elastic_energy_density(spg.stress(i), spg.jacobian(i)) * particles.volume(i);
    Utilities::MPI::sum(ArrayView<const double>(energy, 2), comm, ArrayView<double>(energy, 2));
    result.elastic_before = energy[0];
    result.elastic_after  = energy[1];
    return result;
  }
} // namespace shard::coupling
