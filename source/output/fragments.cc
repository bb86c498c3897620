// SPDX-License-Identifier: LGPL-2.1-or-later
#include <shard/fe/hex_kernel.h>
#include <shard/output/fragments.h>

#include <deal.II/base/mpi.h>

#include <Eigen/Eigenvalues>

#include <algorithm>
#include <cmath>
#include <iomanip>
#include <limits>
#include <map>
#include <sstream>
#include <string>

namespace shard::output
{
  using namespace dealii;

  void
  MassMoments::add(const std::array<double, 3> &x, const double m, const double V)
  {
    if (!has_reference)
      {
        reference     = x;
        has_reference = true;
      }
    const double r[3] = {x[0] - reference[0], x[1] - reference[1], x[2] - reference[2]};
    mass += m;
    volume += V;
    own += m * std::cbrt(V * V) / 12;
    for (unsigned int c = 0; c < 3; ++c)
      first[c] += m * r[c];
    second[0] += m * r[0] * r[0];
    second[1] += m * r[1] * r[1];
    second[2] += m * r[2] * r[2];
    second[3] += m * r[1] * r[2];
    second[4] += m * r[0] * r[2];
    second[5] += m * r[0] * r[1];
  }

  void
  MassMoments::merge(const MassMoments &o)
  {
    if (!o.has_reference)
      return;
    if (!has_reference)
      {
        *this = o;
        return;
      }
    // x - a = (x - b) + (b - a): P += P_o + M_o s, Q += Q_o + P_o s^T + s P_o^T + M_o s s^T.
    const double       s[3] = {o.reference[0] - reference[0], o.reference[1] - reference[1],
                               o.reference[2] - reference[2]};
    const unsigned int i[6] = {0, 1, 2, 1, 0, 0}, j[6] = {0, 1, 2, 2, 2, 1};
    for (unsigned int k = 0; k < 6; ++k)
      second[k] += o.second[k] + o.first[i[k]] * s[j[k]] + s[i[k]] * o.first[j[k]] + o.mass * s[i[k]] * s[j[k]];
    for (unsigned int c = 0; c < 3; ++c)
      first[c] += o.first[c] + o.mass * s[c];
    mass += o.mass;
    volume += o.volume;
    own += o.own;
  }

  void
  MassMoments::pack(std::vector<double> &out) const
  {
    out.push_back(has_reference ? 1. : 0.);
    out.push_back(mass);
    out.push_back(volume);
    out.push_back(own);
    out.insert(out.end(), reference.begin(), reference.end());
    out.insert(out.end(), first.begin(), first.end());
    out.insert(out.end(), second.begin(), second.end());
  }

  MassMoments
  MassMoments::unpack(const double *values)
  {
    MassMoments m;
    m.has_reference = values[0] != 0;
    m.mass          = values[1];
    m.volume        = values[2];
    m.own           = values[3];
    std::copy(values + 4, values + 7, m.reference.begin());
    std::copy(values + 7, values + 10, m.first.begin());
    std::copy(values + 10, values + 16, m.second.begin());
    return m;
  }

  std::array<double, 6>
  MassMoments::covariance() const
  {
    std::array<double, 6> C{};
    if (!(mass > 0))
      return C;
    const double       c[3] = {first[0] / mass, first[1] / mass, first[2] / mass};
    const unsigned int i[6] = {0, 1, 2, 1, 0, 0}, j[6] = {0, 1, 2, 2, 2, 1};
    for (unsigned int k = 0; k < 6; ++k)
      C[k] = second[k] / mass - c[i[k]] * c[j[k]] + (k < 3 ? own / mass : 0.);
    return C;
  }

  FragmentShape
  fragment_shape(const MassMoments &moments)
  {
    FragmentShape shape;
    shape.volume              = moments.volume;
    shape.equivalent_diameter = std::cbrt(6 * std::max(moments.volume, 0.) / M_PI);
    const auto      C         = moments.covariance();
    Eigen::Matrix3d A;
    A << C[0], C[5], C[4], C[5], C[1], C[3], C[4], C[3], C[2];
    // The iterative solver, not computeDirect(): the closed form loses the small eigenvalue of
    // a long fragment to the round-off of the large one.
    const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> solver(A, Eigen::EigenvaluesOnly);
    const auto                                          &l = solver.eigenvalues(); // ascending
    shape.principal_variances = {{l[2], l[1], l[0]}};
    if (!(l[2] > 0))
      shape.aspect_ratio = 1;
    else if (!(l[0] > 0))
      shape.aspect_ratio = std::numeric_limits<double>::infinity();
    else
      shape.aspect_ratio = std::sqrt(l[2] / l[0]);
    return shape;
  }

  void
  classify(std::vector<Fragment> &fragments, const unsigned int dust_nodes, const std::array<double, 3> &axis)
  {
    // The heaviest fragment of each body is the body; the rest is debris. Masses within 1e-12
    // of each other count as equal and the smaller id wins, so that the two halves of a
    // symmetric break (equal masses up to the summation order) give the same answer at any
    // number of ranks.
    std::map<unsigned int, std::size_t> heaviest;
    for (std::size_t k = 0; k < fragments.size(); ++k)
      {
        const auto &f  = fragments[k];
        const auto  it = heaviest.find(f.body);
        if (it == heaviest.end())
          heaviest[f.body] = k;
        else
          {
            const auto &h = fragments[it->second];
            const double tie = 1e-12 * std::max(f.mass, h.mass);
            if (f.mass > h.mass + tie || (std::abs(f.mass - h.mass) <= tie && f.id < h.id))
              it->second = k;
          }
      }
    for (std::size_t k = 0; k < fragments.size(); ++k)
      {
        auto &f  = fragments[k];
        f.debris = heaviest.at(f.body) != k;
        f.dust   = f.debris && f.nodes < dust_nodes;
        const auto  &v = f.velocity;
        const double along = v[0] * axis[0] + v[1] * axis[1] + v[2] * axis[2];
        const double across =
          std::hypot(v[1] * axis[2] - v[2] * axis[1], v[2] * axis[0] - v[0] * axis[2], v[0] * axis[1] - v[1] * axis[0]);
        f.cone_angle = std::atan2(across, along) * 180 / M_PI;
      }
  }

  FragmentSummary
  summarize(const std::vector<Fragment> &fragments)
  {
    FragmentSummary s;
    s.count = fragments.size();
    std::vector<double>                    coarse;
    std::vector<std::pair<double, double>> angles; // (cone angle, mass) of the debris
    double                                 weighted_angle = 0;
    for (const auto &f : fragments)
      {
        s.mass += f.mass;
        if (!f.debris)
          {
            s.body_mass += f.mass;
            continue;
          }
        ++s.debris_count;
        s.debris_mass += f.mass;
        if (f.dust)
          {
            ++s.dust_count;
            s.dust_mass += f.mass;
          }
        else
          {
            s.coarse_debris_mass += f.mass;
            coarse.push_back(f.mass);
          }
        s.largest_debris_mass  = std::max(s.largest_debris_mass, f.mass);
        s.fastest_debris_speed = std::max(s.fastest_debris_speed, std::hypot(f.velocity[0], f.velocity[1], f.velocity[2]));
        weighted_angle += f.mass * f.cone_angle;
        angles.emplace_back(f.cone_angle, f.mass);
      }
    if (s.debris_mass > 0)
      {
        s.dust_fraction          = s.dust_mass / s.debris_mass;
        s.coarse_debris_fraction = s.coarse_debris_mass / s.debris_mass;
        s.cone_angle_mean        = weighted_angle / s.debris_mass;
        // The smallest angle whose cone holds at least 90 % of the debris mass (a relative
        // margin of 1e-12 so that round-off in the running sum does not pass the next angle).
        std::sort(angles.begin(), angles.end());
        double within = 0;
        for (const auto &[angle, m] : angles)
          {
            within += m;
            s.cone_angle_90 = angle;
            if (within >= 0.9 * s.debris_mass * (1 - 1e-12))
              break;
          }
      }
    if (!coarse.empty())
      {
        std::sort(coarse.begin(), coarse.end());
        const std::size_t n = coarse.size();
        s.median_coarse_debris_mass = n % 2 ? coarse[n / 2] : 0.5 * (coarse[n / 2 - 1] + coarse[n / 2]);
      }
    return s;
  }

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
    // Body and lumped volume (V_e / 8 of every cell at the node, converted or not, as the
    // lumped mass: HexForce::add_lumped_mass) of every owned node.
    node_id_.assign(pt.locally_owned_size() / 3, 0);
    body_.assign(pt.locally_owned_size() / 3, 0);
    mesh::Vector volume;
    discretization.initialize_vector(volume);
    for (const auto &cell : discretization.dof_handler().active_cell_iterators())
      if (cell->is_locally_owned())
        {
          double x[8][3], B[8][3];
          for (unsigned int a = 0; a < 8; ++a)
            for (unsigned int i = 0; i < 3; ++i)
              x[a][i] = cell->vertex(a)[i];
          const double ve = fe::hex_volume_gradient(x, B);
          for (const unsigned int v : cell->vertex_indices())
            {
              const auto g = cell->vertex_dof_index(v, 0);
              volume.local_element(pt.global_to_local(g)) += ve / 8;
              if (pt.in_local_range(g))
                {
                  node_id_[pt.global_to_local(g) / 3] = discretization.vertex_key(cell->vertex_index(v));
                  body_[pt.global_to_local(g) / 3]    = cell->material_id();
                }
            }
        }
    volume.compress(VectorOperation::add);
    volume_.assign(pt.locally_owned_size() / 3, 0.);
    for (unsigned int j = 0; j < pt.locally_owned_size(); j += 3)
      volume_[j / 3] = volume.local_element(j);
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

    // Sums per label on this rank, then over ranks (rank order), sorted by label: nodes,
    // particles, m, m x (3), m v (3), ke, m X (3); the body (smallest index); the mass moments.
    const auto &X = discretization_->reference_positions();
    struct Sums
    {
      std::array<double, 13> s{};
      double                 body = std::numeric_limits<double>::max();
      MassMoments            moments;
    };
    constexpr unsigned int             record = 1 + 13 + 1 + MassMoments::n_values; // id first
    std::map<unsigned long long, Sums> local;
    for (unsigned int j = 0; j < n; j += 3)
      {
        auto &sums = local[static_cast<unsigned long long>(label.local_element(j))];
        auto &s    = sums.s;
        s[0] += 1;
        s[1] += particle_[j / 3];
        const double m = mass.local_element(j);
        s[2] += m;
        std::array<double, 3> x;
        for (unsigned int c = 0; c < 3; ++c)
          {
            x[c] = X.local_element(j + c) + d.local_element(j + c);
            s[3 + c] += m * x[c];
            s[6 + c] += m * v.local_element(j + c);
            s[9] += 0.5 * m * v.local_element(j + c) * v.local_element(j + c);
            s[10 + c] += m * X.local_element(j + c);
          }
        sums.body = std::min(sums.body, static_cast<double>(body_[j / 3]));
        sums.moments.add(x, m, volume_[j / 3]);
      }
    std::vector<double> flat;
    for (const auto &[id, sums] : local)
      {
        flat.push_back(static_cast<double>(id));
        flat.insert(flat.end(), sums.s.begin(), sums.s.end());
        flat.push_back(sums.body);
        sums.moments.pack(flat);
      }
    std::map<unsigned long long, Sums> total;
    // Only rank 0 writes the tables: the records go there, not to every rank (with much dust
    // there are about as many records as particles).
    for (const auto &part : Utilities::MPI::gather(comm, flat, 0))
      for (std::size_t k = 0; k < part.size(); k += record)
        {
          auto &sums = total[static_cast<unsigned long long>(part[k])];
          for (unsigned int c = 0; c < 13; ++c)
            sums.s[c] += part[k + 1 + c];
          sums.body = std::min(sums.body, part[k + 14]);
          sums.moments.merge(MassMoments::unpack(&part[k + 15]));
        }
    std::vector<Fragment> out;
    for (const auto &[id, sums] : total)
      {
        const auto &s = sums.s;
        Fragment    f;
        f.id        = id;
        f.nodes     = static_cast<unsigned long long>(s[0]);
        f.particles = static_cast<unsigned long long>(s[1]);
        f.mass      = s[2];
        for (unsigned int c = 0; c < 3; ++c)
          {
            f.centre[c]   = s[2] > 0 ? s[3 + c] / s[2] : 0.;
            f.velocity[c] = s[2] > 0 ? s[6 + c] / s[2] : 0.;
            f.origin[c]   = s[2] > 0 ? s[10 + c] / s[2] : 0.;
          }
        f.kinetic_energy          = s[9];
        f.body                    = static_cast<unsigned int>(sums.body);
        const auto shape          = fragment_shape(sums.moments);
        f.volume                  = shape.volume;
        f.equivalent_diameter     = shape.equivalent_diameter;
        f.aspect_ratio            = shape.aspect_ratio;
        out.push_back(f);
      }
    return out;
  }
  std::string
  summary_json(const std::vector<Fragment> &fragments, const double time, const unsigned int dust_particles,
               const std::array<double, 3> &axis)
  {
    // Debris and dust (doc/manual/failure.md, "Fragments").
    const auto s      = summarize(fragments);
    const auto number = [](const double x) {
      std::ostringstream o;
      o << std::setprecision(17) << x;
      return std::isfinite(x) ? o.str() : std::string("null");
    };
    std::ostringstream j;
    j << "{\"time\": " << number(time) << ", \"count\": " << s.count << ", \"mass\": " << number(s.mass)
      << ", \"dust_particles\": " << dust_particles << ", \"debris_axis\": [" << number(axis[0]) << ", "
      << number(axis[1]) << ", " << number(axis[2]) << "], \"body_mass\": " << number(s.body_mass)
      << ", \"debris_count\": " << s.debris_count << ", \"debris_mass\": " << number(s.debris_mass)
      << ", \"dust_count\": " << s.dust_count << ", \"dust_mass\": " << number(s.dust_mass)
      << ", \"dust_fraction\": " << number(s.dust_fraction)
      << ", \"coarse_debris_mass\": " << number(s.coarse_debris_mass)
      << ", \"coarse_debris_fraction\": " << number(s.coarse_debris_fraction)
      << ", \"largest_debris_mass\": " << number(s.largest_debris_mass)
      << ", \"fastest_debris_speed\": " << number(s.fastest_debris_speed)
      << ", \"median_coarse_debris_mass\": " << number(s.median_coarse_debris_mass)
      << ", \"debris_cone_angle_mean\": " << number(s.cone_angle_mean)
      << ", \"debris_cone_angle_90\": " << number(s.cone_angle_90) << "}";
    return j.str();
  }
} // namespace shard::output
