// SPDX-License-Identifier: LGPL-2.1-or-later
#include <shard/base/parallel.h>
#include <shard/base/sections.h>
#include <shard/base/tensor.h>
#include <shard/fe/hex_force.h>
#include <shard/fe/hex_kernel.h>

#include <deal.II/base/mpi.h>

#include <algorithm>
#include <cmath>
#include <exception>
#include <numeric>
#include <sstream>

namespace shard::fe
{
  using namespace dealii;

  namespace
  {
    constexpr unsigned int batch_size = materials::point_batch_size;
    /// Largest number of batches per block of the threaded loop (a block runs on one thread).
    constexpr unsigned int max_batches_per_block = 16;
    /// Smallest number of blocks the batches are cut into, where there are batches enough.
    constexpr unsigned int min_blocks = 64;
  }

  bool
  HexForce::declare_parameters(ParameterHandler &prm)
  {
    if (!first_declaration())
      return false;
    prm.enter_subsection(sections::finite_elements);
    prm.add_parameter("hourglass type", hourglass_type_,
                      "Flanagan-Belytschko hourglass control: viscous (force q_hg rho c V^(2/3) / 4 times the "
                      "hourglass velocity; no stiffening in plastic flow; like LS-DYNA type 2) "
                      "or stiffness (forces grow with the hourglass displacement, stiffness "
                      "q_hg rho c^2 (B:B) / (8 V); LS-DYNA type 4 analogue).",
                      Patterns::Selection("viscous|stiffness"));
    prm.add_parameter("hourglass coefficient", hourglass_coefficient_,
                      "Hourglass coefficient q_hg of the chosen form. Unit: 1. Range: 0 to 0.3.",
                      Patterns::Double(0, 0.3));
    prm.add_parameter("bulk viscosity linear", viscosity_.q1,
                      "Linear coefficient Q1 of the element bulk viscosity q = rho L (Q2 L tr(D)^2 - Q1 c tr(D)) "
                      "(L = V / A_max), a pressure added in compression (tr(D) < 0) only and not stored, like "
                      "LS-DYNA's default for solids (0.06, 1.5); it spreads shocks over a few elements and "
                      "damps the ringing behind them. Its work is part of the internal energy; it lowers the "
                      "element step to L / (c (sqrt(1 + r^2) + r)), r = Q1 - Q2 L tr(D) / c. Unit: 1. Range: "
                      "0 to 1.",
                      Patterns::Double(0, 1));
    prm.add_parameter("bulk viscosity quadratic", viscosity_.q2,
                      "Quadratic coefficient Q2 of the element bulk viscosity. Unit: 1. Range: 0 to 4.",
                      Patterns::Double(0, 4));
    prm.leave_subsection();
    return true;
  }

  void
  HexForce::check_parameters(const base::PrmSource &source) const
  {
    if (!(hourglass_coefficient_ >= 0 && hourglass_coefficient_ <= 0.3))
      source.fail(sections::finite_elements + "/hourglass coefficient", std::to_string(hourglass_coefficient_),
                  "must be in [0, 0.3]. Unit: 1.");
  }

  void
  HexForce::prepare(const mesh::Discretization &discretization, const materials::MaterialLibrary &library,
                    const std::vector<bool> &converted_cells)
  {
    discretization_         = &discretization;
    library_                = &library;
    viscous_                = hourglass_type_ == "viscous";
    const auto &dh          = discretization.dof_handler();
    const auto &partitioner = *discretization.partitioner();
    const auto &X           = discretization.reference_positions();
    const auto &bodies      = discretization.bodies();

    // Material of each body -> group index (one group per material).
    std::vector<std::string> material_names;
    std::vector<unsigned int> group_of_body;
    for (const auto &b : bodies)
      {
        auto it = std::find(material_names.begin(), material_names.end(), b.material);
        group_of_body.push_back(static_cast<unsigned int>(it - material_names.begin()));
        if (it == material_names.end())
          material_names.push_back(b.material);
      }

    struct Raw
    {
      unsigned int  group, cell, body;
      std::uint64_t id;
      unsigned int  nodes[8];
    };
    std::vector<Raw> raw;
    for (const auto &cell : dh.active_cell_iterators())
      if (cell->is_locally_owned() &&
          !(cell->active_cell_index() < converted_cells.size() && converted_cells[cell->active_cell_index()]))
        {
          Raw r;
          r.body  = cell->material_id();
          r.group = group_of_body[r.body];
          r.cell  = cell->active_cell_index();
          r.id    = cell->id().get_coarse_cell_id();
          for (unsigned int v = 0; v < 8; ++v)
            r.nodes[v] = partitioner.global_to_local(cell->vertex_dof_index(v, 0));
          raw.push_back(r);
        }
    std::stable_sort(raw.begin(), raw.end(), [](const Raw &a, const Raw &b) { return a.group < b.group; });

    const unsigned int n = raw.size();
    nodes_.resize(8 * n);
    cell_index_.resize(n);
    cell_id_.resize(n);
    body_.resize(n);
    std::vector<unsigned int> group_of(n);
    volume0_.resize(n);
    element_dt_.assign(n, 1e300);
    stress_.assign(6 * n, 0.);
    q_.assign(n, 0.);
    hourglass_.assign(12 * n, 0.);
    element_of_cell_.assign(discretization.triangulation().n_active_cells(), -1);
    std::vector<double> centroid(3 * n, 0.); // reference centroids, for fields of the position
    for (unsigned int e = 0; e < n; ++e)
      {
        element_of_cell_[raw[e].cell] = static_cast<int>(e);
        std::copy(raw[e].nodes, raw[e].nodes + 8, &nodes_[8 * e]);
        cell_index_[e] = raw[e].cell;
        cell_id_[e]    = raw[e].id;
        body_[e]       = raw[e].body;
        group_of[e]    = raw[e].group;
        double x[8][3], B[8][3];
        for (unsigned int a = 0; a < 8; ++a)
          for (unsigned int i = 0; i < 3; ++i)
            {
              x[a][i] = X.local_element(raw[e].nodes[a] + i);
              centroid[3 * e + i] += x[a][i] / 8.;
            }
        volume0_[e] = hex_volume_gradient(x, B);
        AssertThrow(volume0_[e] > 0, ExcMessage("inverted element in the input mesh (body " +
                                                bodies[raw[e].body].name + ")"));
      }
    std::vector<const materials::Material *> materials;
    for (const auto &name : material_names)
      materials.push_back(&library.get(name));
    points_.build(materials, group_of, centroid.data());
    build_batches();
  }

  void
  HexForce::add_lumped_mass(mesh::Vector &mass) const
  {
    const auto &pt = *discretization_->partitioner();
    for (const auto &cell : discretization_->dof_handler().active_cell_iterators())
      if (cell->is_locally_owned())
        {
          double x[8][3], B[8][3];
          for (unsigned int a = 0; a < 8; ++a)
            for (unsigned int i = 0; i < 3; ++i)
              x[a][i] = cell->vertex(a)[i];
          const double rho = library_->get(discretization_->bodies()[cell->material_id()].material).density();
          const double m   = rho * hex_volume_gradient(x, B) / 8.;
          for (unsigned int a = 0; a < 8; ++a)
            for (unsigned int i = 0; i < 3; ++i)
              mass.local_element(pt.global_to_local(cell->vertex_dof_index(a, i))) += m;
        }
  }

  void
  HexForce::remove_elements(const std::vector<unsigned int> &elements)
  {
    std::vector<bool> drop(n_local_elements(), false);
    for (const unsigned int e : elements)
      drop[e] = true;
    // Elements stay in their order (the material groups are contiguous in it).
    unsigned int n = 0;
    for (unsigned int e = 0; e < drop.size(); ++e)
      if (!drop[e])
        {
          std::copy(&nodes_[8 * e], &nodes_[8 * e] + 8, &nodes_[8 * n]);
          std::copy(&stress_[6 * e], &stress_[6 * e] + 6, &stress_[6 * n]);
          q_[n] = q_[e];
          std::copy(&hourglass_[12 * e], &hourglass_[12 * e] + 12, &hourglass_[12 * n]);
          cell_index_[n] = cell_index_[e];
          cell_id_[n]    = cell_id_[e];
          body_[n]       = body_[e];
          volume0_[n]    = volume0_[e];
          element_dt_[n] = element_dt_[e];
          ++n;
        }
    points_.remove(drop);
    nodes_.resize(8 * n);
    stress_.resize(6 * n);
    q_.resize(n);
    hourglass_.resize(12 * n);
    cell_index_.resize(n);
    cell_id_.resize(n);
    body_.resize(n);
    volume0_.resize(n);
    element_dt_.resize(n);
    std::fill(element_of_cell_.begin(), element_of_cell_.end(), -1);
    for (unsigned int e = 0; e < n; ++e)
      element_of_cell_[cell_index_[e]] = static_cast<int>(e);
    build_batches();
  }

  void
  HexForce::relocalize(const Utilities::MPI::Partitioner &old_partitioner,
                       const Utilities::MPI::Partitioner &new_partitioner)
  {
    for (auto &j : nodes_)
      j = new_partitioner.global_to_local(old_partitioner.local_to_global(j));
  }

  double
  HexForce::initial_stable_dt() const
  {
    const auto &X  = discretization_->reference_positions();
    double      dt = 1e300;
    for (unsigned int e = 0; e < n_local_elements(); ++e)
      {
        double x[8][3];
        for (unsigned int a = 0; a < 8; ++a)
          for (unsigned int i = 0; i < 3; ++i)
            x[a][i] = X.local_element(nodes_[8 * e + a] + i);
        const auto *m = &points_.material(e);
        if (m->rigid())
          continue; // no internal force, no step limit
        dt = std::min(dt, volume0_[e] / hex_max_face_area(x) / m->initial_wave_speed());
      }
    // The linear bulk viscosity lowers the step from the first force evaluation on.
    dt /= viscosity_.initial_step_factor();
    return Utilities::MPI::min(dt, discretization_->communicator());
  }

  double
  HexForce::state_value(const unsigned int e, const std::string &name) const
  {
    return points_.state_value(e, name);
  }

  std::string
  HexForce::describe(const unsigned int e, const mesh::Vector &d) const
  {
    const auto &X = discretization_->reference_positions();
    double      c[3] = {0, 0, 0};
    for (unsigned int a = 0; a < 8; ++a)
      for (unsigned int i = 0; i < 3; ++i)
        c[i] += (X.local_element(nodes_[8 * e + a] + i) + d.local_element(nodes_[8 * e + a] + i)) / 8;
    std::ostringstream out;
    out << "element " << cell_id_[e] << " of body '" << discretization_->bodies()[body_[e]].name << "' at ("
        << c[0] << ", " << c[1] << ", " << c[2] << ") m";
    return out.str();
  }

  void
  HexForce::fail(const unsigned int e, const mesh::Vector &d, const unsigned int step,
                 const std::string &what) const
  {
    throw Instability("step " + std::to_string(step) + ": " + what + " in " + describe(e, d));
  }

  void
  HexForce::build_batches()
  {
    // The batches of the material groups, in element order (rigid bodies have none).
    const auto &batches = points_.batches();
    // Blocks of batches_per_block_ consecutive batches: a block runs on one thread in element order
    // (the neighbours of an element are mostly near it in that order, so its nodes are still in
    // cache). Greedy colouring of the blocks: colour c takes, in block order, every block not yet
    // coloured that shares no node with a block already of colour c. It depends on the mesh and
    // the element order only, so the order in which a node receives its element forces (colour by
    // colour, within a block in element order) is the same for any thread count.
    // Large blocks keep the cache reuse of the serial loop, many blocks balance the threads: at
    // least min_blocks blocks where possible. The block size depends on the elements of the
    // rank only, never on the thread count.
    batches_per_block_ =
      std::clamp<unsigned int>(batches.size() / min_blocks, 1, max_batches_per_block);
    const unsigned int n_blocks = base::n_chunks(batches.size(), batches_per_block_);
    std::vector<int>          colour(n_blocks, -1);
    std::vector<unsigned int> stamp;
    for (const unsigned int j : nodes_)
      if (j / 3 + 1 > stamp.size())
        stamp.resize(j / 3 + 1, 0);
    colour_offsets_.assign(1, 0);
    block_order_.clear();
    for (unsigned int c = 0; block_order_.size() < n_blocks; ++c)
      {
        for (unsigned int b = 0; b < n_blocks; ++b)
          if (colour[b] < 0)
            {
              const unsigned int  last_batch = std::min<unsigned int>(batches.size(), (b + 1) * batches_per_block_) - 1;
              const unsigned int *first      = &nodes_[8 * batches[b * batches_per_block_].begin],
                                 *last       = &nodes_[8 * batches[last_batch].end];
              if (std::any_of(first, last, [&](unsigned int j) { return stamp[j / 3] == c + 1; }))
                continue;
              std::for_each(first, last, [&](unsigned int j) { stamp[j / 3] = c + 1; });
              colour[b] = static_cast<int>(c);
              block_order_.push_back(b);
            }
        colour_offsets_.push_back(block_order_.size());
      }
  }

  ForceResult
  HexForce::add_internal_forces(const mesh::Vector &d, const mesh::Vector &v, const double dt,
                                const unsigned int step, mesh::Vector &f)
  {
    const auto  &X  = discretization_->reference_positions();
    const double *Xp = X.begin(), *dp = d.begin(), *vp = v.begin();
    double       *fp = f.begin();

    // One partial result and one error slot per batch, combined in batch order below.
    const auto                     &batches  = points_.batches();
    const unsigned int              n_batches = batches.size();
    std::vector<ForceResult>        partial(n_batches);
    std::vector<std::exception_ptr> error(n_batches);

    const auto process = [&](const unsigned int bi) {
      const auto  &bat    = batches[bi];
      ForceResult &result = partial[bi];
      // Per-batch scratch: kinematics of pass 1 used by the material call and pass 2.
      struct Scratch
      {
        double B[8][3];
        double gamma[4][8];
        double q[4][3];
        double rotation[3][3];
        double volume, volume_mid, max_area;
        double stress_old[6];
      };
      Scratch            scratch[batch_size];
      double             de[batch_size * 6], J[batch_size], length[batch_size], c[batch_size];
      const unsigned int b0 = bat.begin;
      const unsigned int nb = bat.end - bat.begin;
      // Pass 1: kinematics, objective rotation of the stored stress.
      for (unsigned int k = 0; k < nb; ++k)
        {
          const unsigned int  e = b0 + k;
          const unsigned int *n = &nodes_[8 * e];
          Scratch            &s = scratch[k];
          double              x[8][3], xm[8][3], vel[8][3];
          for (unsigned int a = 0; a < 8; ++a)
            for (unsigned int i = 0; i < 3; ++i)
              {
                const unsigned int j = n[a] + i;
                vel[a][i]            = vp[j];
                x[a][i]              = Xp[j] + dp[j];
                xm[a][i]             = x[a][i] - 0.5 * dt * vel[a][i];
              }
          double Bm[8][3];
          s.volume_mid = hex_volume_gradient(xm, Bm);
          s.volume     = hex_volume_gradient(x, s.B);
          if (!(s.volume > 0) || !(s.volume_mid > 0))
            fail(e, d, step, "inverted element (volume " + std::to_string(s.volume) + " m^3)");
          // Mean velocity gradient at mid-step.
          double       L[3][3] = {};
          const double inv_vm  = 1. / s.volume_mid;
          for (unsigned int a = 0; a < 8; ++a)
            for (unsigned int i = 0; i < 3; ++i)
              for (unsigned int j = 0; j < 3; ++j)
                L[i][j] += vel[a][i] * Bm[a][j];
          double W[3][3];
          for (unsigned int i = 0; i < 3; ++i)
            for (unsigned int j = 0; j < 3; ++j)
              {
                L[i][j] *= inv_vm;
              }
          for (unsigned int i = 0; i < 3; ++i)
            for (unsigned int j = 0; j < 3; ++j)
              W[i][j] = 0.5 * (L[i][j] - L[j][i]);
          double *dek = &de[6 * k];
          dek[0]      = dt * L[0][0];
          dek[1]      = dt * L[1][1];
          dek[2]      = dt * L[2][2];
          dek[3]      = 0.5 * dt * (L[1][2] + L[2][1]);
          dek[4]      = 0.5 * dt * (L[0][2] + L[2][0]);
          dek[5]      = 0.5 * dt * (L[0][1] + L[1][0]);
          tensor::hughes_winget_rotation(W, dt, s.rotation);
          double *sig = &stress_[6 * e];
          tensor::rotate_symmetric(s.rotation, sig);
          std::copy(sig, sig + 6, s.stress_old);
          J[k]       = s.volume / volume0_[e];
          s.max_area = hex_max_face_area(x);
          length[k]  = s.volume / s.max_area;
          // Hourglass shape vectors and rates at the end of the step.
          hex_hourglass_vectors(x, s.B, s.volume, s.gamma);
          for (unsigned int m = 0; m < 4; ++m)
            for (unsigned int i = 0; i < 3; ++i)
              {
                double q = 0;
                for (unsigned int a = 0; a < 8; ++a)
                  q += s.gamma[m][a] * vel[a][i];
                s.q[m][i] = q;
              }
        }

      // One material call per batch.
      points_.update(bat, dt, de, J, length, stress_.data(), c);

      // Pass 2: energy, nodal forces, hourglass control, time step.
      const double rho0 = points_.groups()[bat.group].material->density();
      for (unsigned int k = 0; k < nb; ++k)
        {
          const unsigned int e   = b0 + k;
          Scratch           &s   = scratch[k];
          const double      *sig = &stress_[6 * e];
          const double      *dek = &de[6 * k];
          double work = materials::stress_work(s.stress_old, sig, dek, s.volume_mid,
                                               materials::WorkOrder::normal_then_shear);
          if (!std::isfinite(work) || !std::isfinite(c[k]))
            fail(e, d, step, "non-finite stress (sigma_xx = " + std::to_string(sig[0]) + " Pa)");
          const double rho = rho0 / J[k];
          // Bulk viscosity in compression (not stored), its work and step limit.
          const double trd = dek[0] + dek[1] + dek[2];
          const double q   = viscosity_.apply(rho, length[k], c[k], trd, dt, s.volume_mid, q_[e], work);
          result.internal_energy += work;
          element_dt_[e] = viscosity_.stable_step(length[k], c[k], trd, dt);
          result.stable_dt = std::min(result.stable_dt, element_dt_[e]);

          // Stiffness hourglass control: the hourglass forces rotate with the element and
          // grow with the hourglass displacement increment.
          double      *h     = &hourglass_[12 * e];
          double       hg_work = 0;
          if (viscous_)
            {
              // Viscous form: the hourglass force follows the hourglass velocity. The
              // coefficient q rho c V^(2/3) / 4 stays bounded relative to the nodal mass when
              // the element flattens, so the damping term is stable at the element step.
              const double v13     = std::cbrt(s.volume);
              const double damping = 0.25 * hourglass_coefficient_ * rho * c[k] * v13 * v13;
              for (unsigned int m = 0; m < 4; ++m)
                for (unsigned int i = 0; i < 3; ++i)
                  {
                    h[3 * m + i] = damping * s.q[m][i];
                    hg_work += dt * s.q[m][i] * h[3 * m + i];
                  }
            }
          else
            {
              // Stiffness form: the stored forces rotate with the element and grow with the
              // hourglass displacement increment.
              double b2 = 0;
              for (unsigned int a = 0; a < 8; ++a)
                b2 += s.B[a][0] * s.B[a][0] + s.B[a][1] * s.B[a][1] + s.B[a][2] * s.B[a][2];
              const double stiffness = hourglass_coefficient_ * rho * c[k] * c[k] * b2 / (8. * s.volume);
              for (unsigned int m = 0; m < 4; ++m)
                {
                  double r[3];
                  for (unsigned int i = 0; i < 3; ++i)
                    r[i] = s.rotation[i][0] * h[3 * m] + s.rotation[i][1] * h[3 * m + 1] +
                           s.rotation[i][2] * h[3 * m + 2];
                  for (unsigned int i = 0; i < 3; ++i)
                    {
                      const double inc = stiffness * dt * s.q[m][i];
                      h[3 * m + i]     = r[i] + inc;
                      hg_work += dt * s.q[m][i] * (r[i] + 0.5 * inc);
                    }
                }
            }
          result.hourglass_energy += hg_work;

          const unsigned int *n = &nodes_[8 * e];
          for (unsigned int a = 0; a < 8; ++a)
            {
              const double *B  = s.B[a];
              double       *fa = fp + n[a];
              fa[0] -= (sig[0] - q) * B[0] + sig[5] * B[1] + sig[4] * B[2];
              fa[1] -= sig[5] * B[0] + (sig[1] - q) * B[1] + sig[3] * B[2];
              fa[2] -= sig[4] * B[0] + sig[3] * B[1] + (sig[2] - q) * B[2];
              for (unsigned int m = 0; m < 4; ++m)
                {
                  const double g = s.gamma[m][a];
                  fa[0] -= g * h[3 * m];
                  fa[1] -= g * h[3 * m + 1];
                  fa[2] -= g * h[3 * m + 2];
                }
            }
        }
    };

    // Colour by colour; the blocks of one colour share no node, so they scatter at the same time.
    for (unsigned int col = 0; col + 1 < colour_offsets_.size(); ++col)
      base::for_each_range(colour_offsets_[col + 1] - colour_offsets_[col], 1,
                           [&](const unsigned int begin, const unsigned int end) {
                             for (unsigned int k = begin; k < end; ++k)
                               {
                                 const unsigned int block = block_order_[colour_offsets_[col] + k];
                                 const unsigned int last =
                                   std::min<unsigned int>(n_batches, (block + 1) * batches_per_block_);
                                 for (unsigned int bi = block * batches_per_block_; bi < last; ++bi)
                                   try
                                     {
                                       process(bi);
                                     }
                                   catch (...)
                                     {
                                       error[bi] = std::current_exception();
                                     }
                               }
                           });
    // The failure of the lowest batch (its first element that failed), whatever the thread count.
    for (const auto &e : error)
      if (e)
        std::rethrow_exception(e);
    ForceResult result;
    for (const auto &p : partial)
      {
        result.internal_energy += p.internal_energy;
        result.hourglass_energy += p.hourglass_energy;
        result.stable_dt = std::min(result.stable_dt, p.stable_dt);
      }
    return result;
  }
} // namespace shard::fe
