// SPDX-License-Identifier: LGPL-2.1-or-later
#include <shard/base/sections.h>
#include <shard/base/tensor.h>
#include <shard/particles/bond_failure.h>

#include <deal.II/base/mpi.h>

#include <algorithm>
#include <cmath>

namespace shard::particles
{
  using namespace dealii;

  namespace
  {
    const char *const criterion_names = "none|plastic strain|scaled damage|principal stress|principal strain";

    BondCriterion
    criterion_of(const std::string &text)
    {
      if (text == "plastic strain")
        return BondCriterion::plastic_strain;
      if (text == "scaled damage")
        return BondCriterion::scaled_damage;
      if (text == "principal stress")
        return BondCriterion::principal_stress;
      if (text == "principal strain")
        return BondCriterion::principal_strain;
      return BondCriterion::none;
    }
  } // namespace

  BondFailure::BondFailure(const materials::MaterialLibrary &library)
    : library_(library)
  {}

  bool
  BondFailure::declare_parameters(ParameterHandler &prm)
  {
    bool added = false;
    prm.enter_subsection(sections::particles);
    prm.enter_subsection("bond failure");
    if (!declared_)
      {
        declared_ = added = true;
        prm.add_parameter("check interval", check_interval_,
                          "Steps between two tests of the bonds (after the force of the step). Unit: steps. "
                          "Range: >= 1.",
                          Patterns::Integer(1));
        prm.add_parameter("rule", rule_text_,
                          "Which particle values of a bond are compared: 'mean' breaks the bond when the mean of "
                          "the two normalized values q/q_c reaches 1, 'either' when one end reaches its threshold, "
                          "'both' when both do, 'tension' when the mean reaches 1 and the bond is longer than in the "
                          "reference configuration (an opening crack; compressed bonds hold).",
                          Patterns::Selection("mean|either|both|tension"));
        prm.add_parameter("minimum bonds", minimum_bonds_,
                          "A particle left with fewer intact bonds to other particles becomes a free particle: "
                          "all its bonds break; it keeps mass, momentum and state and interacts only by contact. "
                          "Unit: 1. Range: >= 0 (3 keeps linear RK rows possible).",
                          Patterns::Integer(0));
        prm.add_parameter("condition limit", condition_limit_,
                          "A row rebuilt after bonds broke uses Shepard functions (constant consistency, "
                          "bounded gradients) when the reciprocal condition number of its scaled moment matrix "
                          "falls below this value. Rows that keep few or one-sided bonds are otherwise far stiffer "
                          "than the step size allows. Intact bodies have about 0.03 at corners. Unit: 1. "
                          "Range: 0 to 1.",
                          Patterns::Double(0, 1));
      }
    for (const auto &name : library_.names())
      {
        if (declared_materials_.count(name))
          continue;
        declared_materials_.insert(name);
        added    = true;
        auto &st = settings_[name];
        prm.enter_subsection(name);
        prm.add_parameter("criterion", st.criterion_text,
                          "Particle value that breaks the bonds of particles of this material: effective plastic "
                          "strain, K&C scaled damage (0 to 2), largest principal stress, largest principal "
                          "engineering strain; none: only the stretch criterion.",
                          Patterns::Selection(criterion_names));
        prm.add_parameter("threshold", st.threshold,
                          "Critical value q_c of the criterion. Unit: 1 for strains and damage, Pa for stress. "
                          "Range: > 0 when a criterion is chosen.",
                          Patterns::Double(0));
        prm.add_parameter("critical stretch", st.stretch,
                          "A bond breaks when its stretch |x_J - x_I| / |X_J - X_I| exceeds this value or falls "
                          "below its inverse. 0 switches the stretch criterion off. Unit: 1. Range: 0 or > 1.",
                          Patterns::Double(0));
        prm.add_parameter("critical opening", st.opening,
                          "A bond breaks when it has opened by more than this length, |x_J - x_I| - |X_J - X_I| "
                          "> w_c: the crack across it is fully open (for a softening material, the opening at "
                          "which its tensile stress is gone, about 5 G_F / f't for concrete). Compressed bonds "
                          "never break by it, so crushed material stays a continuum. The smaller w_c of the two "
                          "ends applies. 0 switches it off. Unit: m. Range: >= 0.",
                          Patterns::Double(0));
        prm.add_parameter("minimum volume ratio", st.volume_ratio,
                          "A particle of this material whose relative volume J = V / V0 falls below this value "
                          "becomes a free particle (crushed: all its bonds break, mass, momentum and state are "
                          "kept), like LS-DYNA's erosion of negative-volume elements but without deleting mass. "
                          "0 switches it off. Unit: 1. Range: 0 to 1.",
                          Patterns::Double(0, 1));
        prm.leave_subsection();
      }
    prm.leave_subsection();
    prm.leave_subsection();
    return added;
  }

  void
  BondFailure::check_parameters(const base::PrmSource &source) const
  {
    const std::string top = sections::particles + "/bond failure/";
    for (const auto &[name, st] : settings_)
      {
        if (st.criterion_text != "none" && !(st.threshold > 0))
          source.fail(top + name + "/threshold", std::to_string(st.threshold),
                      "> 0 when 'criterion' is '" + st.criterion_text + "'.");
        if (!(st.opening >= 0) || !std::isfinite(st.opening))
          source.fail(top + name + "/critical opening", std::to_string(st.opening), "a finite length >= 0 m (0: off).");
        if (st.stretch != 0 && !(st.stretch > 1))
          source.fail(top + name + "/critical stretch", std::to_string(st.stretch), "0 (off) or > 1.");
        if (!(st.volume_ratio >= 0 && st.volume_ratio < 1))
          source.fail(top + name + "/minimum volume ratio", std::to_string(st.volume_ratio), "0 (off) to below 1.");
      }
  }

  void
  BondFailure::prepare(ParticleSet &particles, const SpgForce &spg, const base::PrmSource &source)
  {
    particles.set_broken_condition_limit(condition_limit_);
    rule_ = rule_text_ == "either" ? BondRule::either :
            rule_text_ == "both"   ? BondRule::both :
            rule_text_ == "tension" ? BondRule::tension :
                                      BondRule::mean;
    const unsigned int n = spg.n_owned();
    criterion_.assign(n, BondCriterion::none);
    threshold_.assign(n, 1.);
    stretch_.assign(n, 0.);
    opening_.assign(n, 0.);
    volume_ratio_.assign(n, 0.);
    slot_.assign(n, -1);
    value_.assign(n, 0.);
    bool any          = false;
    stretch_possible_ = false;
    for (const auto &[name, st] : settings_)
      {
        any |= st.criterion_text != "none" || st.stretch > 0 || st.opening > 0 || st.volume_ratio > 0;
        stretch_possible_ |= st.stretch > 0 || st.opening > 0;
      }
    active_ = spg.active() && any;
    if (!active_)
      return;
    has_bonds_.resize(n);
    for (unsigned int i = 0; i < n; ++i)
      has_bonds_[i] = particles.intact_bonds(i) > 0;
    std::map<const materials::Material *, const std::string *> names;
    for (const auto &name : library_.names())
      names[&library_.get(name)] = &name;
    for (unsigned int i = 0; i < n; ++i)
      {
        const auto        &m    = spg.material(i);
        const std::string &name = *names.at(&m);
        const auto        &st   = settings_.at(name);
        criterion_[i]           = criterion_of(st.criterion_text);
        threshold_[i]           = st.threshold > 0 ? st.threshold : 1.;
        stretch_[i]             = st.stretch;
        opening_[i]             = st.opening;
        volume_ratio_[i]        = st.volume_ratio;
        const char *slot        = criterion_[i] == BondCriterion::plastic_strain ? materials::slot::plastic_strain :
                                  criterion_[i] == BondCriterion::scaled_damage  ? "scaled damage" :
                                                                                   nullptr;
        if (slot)
          {
            const auto slots = m.state_slot_names();
            const auto it    = std::find(slots.begin(), slots.end(), slot);
            if (it == slots.end())
              source.fail(sections::particles + "/bond failure/" + name + "/criterion", st.criterion_text,
                          "a criterion the material's model provides (model '" + m.model_name() +
                            "' has no history slot '" + slot + "').");
            slot_[i] = static_cast<int>(it - slots.begin());
          }
      }
  }

  double
  BondFailure::evaluate(const SpgForce &spg, const unsigned int i) const
  {
    switch (criterion_[i])
      {
        case BondCriterion::plastic_strain:
        case BondCriterion::scaled_damage:
          return spg.state(i)[slot_[i]] / threshold_[i];
        case BondCriterion::principal_stress:
          return tensor::symmetric_eigenvalues(spg.stress(i))[2] / threshold_[i];
        case BondCriterion::principal_strain:
          return (tensor::principal_stretches(spg.deformation_gradient(i))[2] - 1.) / threshold_[i];
        case BondCriterion::none:
          break;
      }
    return 0.;
  }

  std::pair<unsigned long long, unsigned long long>
  BondFailure::update(const mesh::Discretization &discretization, ParticleSet &particles, const SpgForce &spg,
                      mesh::Vector &q)
  {
    bytes_sent_ = 0;
    if (!active_)
      return {0, 0};
    const MPI_Comm comm = discretization.communicator();
    if (q.get_partitioner() != discretization.partitioner())
      discretization.initialize_vector(q);
    const auto        &st = particles.stencils();
    const unsigned int n  = st.n_i;

    // 1. Normalized values and critical stretches of the owned particles, exchanged (0 for a
    // particle without bonds: no bond of it is left to test).
    for (unsigned int i = 0; i < n; ++i)
      {
        value_[i] = evaluate(spg, i);
        q.local_element(particles.local_dof(i))     = has_bonds_[i] ? value_[i] : 0.;
        q.local_element(particles.local_dof(i) + 1) = stretch_[i];
        q.local_element(particles.local_dof(i) + 2) = opening_[i];
      }
    q.update_ghost_values();
    bytes_sent_ += sizeof(double) * q.get_partitioner()->n_import_indices();

    // 2. The bonds of the owned rows. Without critical stretches a row can only lose a bond
    // if its value and the largest value among the coefficients (owned and ghost) together
    // meet the rule; the other rows are skipped (exact: no bond is missed).
    double largest = 0;
    for (unsigned int k = 0; k < st.n_k; ++k)
      largest = std::max(largest, q.local_element(particles.local_dof(k)));
    const auto may_break = [&](const double qi) {
      if (stretch_possible_)
        return true;
      return rule_ == BondRule::mean || rule_ == BondRule::tension ? qi + largest >= 2. :
             rule_ == BondRule::either ? std::max(qi, largest) >= 1. :
                                         qi >= 1.;
    };
    const auto                &u = spg.displacement_rows();
    std::vector<ParticleSet::Bond> bonds;
    for (unsigned int i = 0; i < n; ++i)
      if (has_bonds_[i] && may_break(value_[i]))
        for (unsigned int e = st.g.row_offsets[i]; e < st.g.row_offsets[i + 1]; ++e)
          {
            const unsigned int j = st.g.columns[e];
            if (j == i || !particles.g_entry_intact(e))
              continue;
            const double qi = value_[i], qj = q.local_element(particles.local_dof(j));
            bool         broken = rule_ == BondRule::mean || rule_ == BondRule::tension ? qi + qj >= 2. :
                                  rule_ == BondRule::either                            ? std::max(qi, qj) >= 1. :
                                                                                         std::min(qi, qj) >= 1.;
            const double si = stretch_[i], sj = q.local_element(particles.local_dof(j) + 1);
            const double s  = si > 0 && sj > 0 ? std::min(si, sj) : std::max(si, sj);
            const double wi = opening_[i], wj = q.local_element(particles.local_dof(j) + 2);
            const double w  = wi > 0 && wj > 0 ? std::min(wi, wj) : std::max(wi, wj);
            const bool   need_stretch = (rule_ == BondRule::tension && broken) || (!broken && (s > 0 || w > 0));
            if (need_stretch)
              {
                const Point3 &Xi = particles.compact_position(i), &Xj = particles.compact_position(j);
                double        l0 = 0, l = 0;
                for (unsigned int c = 0; c < 3; ++c)
                  {
                    const double r0 = Xj[c] - Xi[c];
                    const double r  = r0 + u[3 * j + c] - u[3 * i + c];
                    l0 += r0 * r0;
                    l += r * r;
                  }
                if (broken) // tension rule: the crack must open across the bond
                  broken = l > l0;
                if (!broken && s > 0)
                  {
                    const double lambda = std::sqrt(l / l0);
                    broken              = lambda > s || lambda < 1. / s;
                  }
                if (!broken && w > 0)
                  broken = std::sqrt(l) - std::sqrt(l0) > w;
              }
            if (broken)
              {
                const auto a = particles.compact_id(i), b = particles.compact_id(j);
                bonds.emplace_back(std::min(a, b), std::max(a, b));
              }
          }

    // Crushed particles (J below the material's minimum volume ratio) that still have bonds.
    std::vector<unsigned long long> crushed;
    for (unsigned int i = 0; i < n; ++i)
      if (has_bonds_[i] && volume_ratio_[i] > 0 && spg.jacobian(i) < volume_ratio_[i])
        crushed.push_back(particles.compact_id(i));

    // 3. The bonds to the ranks that hold their rows (ParticleSet::spread_bonds: the owners of
    // both ends, then the ranks that hold those particles). 4. Free particles, until none is
    // added, told to the ranks that hold them.
    unsigned long long n_bonds = 0, n_freed = 0;
    if (Utilities::MPI::sum(static_cast<unsigned long long>(bonds.size() + crushed.size()), comm) > 0)
      {
        n_bonds = Utilities::MPI::sum(particles.spread_bonds(comm, bonds, bytes_sent_), comm);
        n_freed = particles.spread_free(comm, crushed, bytes_sent_);
        while (true)
          {
            std::vector<unsigned long long> freed;
            for (const unsigned int i : particles.take_changed_rows())
              {
                if (i >= n)
                  continue;
                const unsigned int left = particles.intact_bonds(i);
                has_bonds_[i]           = left > 0;
                if (left < minimum_bonds_ &&
                    !std::binary_search(particles.free_particles().begin(), particles.free_particles().end(),
                                        particles.compact_id(i)))
                  freed.push_back(particles.compact_id(i));
              }
            if (Utilities::MPI::sum(static_cast<unsigned long long>(freed.size()), comm) == 0)
              break;
            n_freed += particles.spread_free(comm, freed, bytes_sent_);
          }
        n_freed = Utilities::MPI::sum(n_freed, comm);
      }
    n_broken_ += n_bonds;
    n_free_ += n_freed;
    return {n_bonds, n_freed};
  }
} // namespace shard::particles
