// SPDX-License-Identifier: LGPL-2.1-or-later
#include <shard/simulation/energy_balance.h>

#include <deal.II/base/mpi.h>

#include <algorithm>
#include <cmath>
#include <stdexcept>

namespace shard
{
  EnergyBalance::Totals
  EnergyBalance::reduce(const ContactEnergies &contact, MPI_Comm comm)
  {
    // One reduction of the energy terms and momentum.
    const double local[14] = {kick_.kinetic,        internal_ + conversion_elastic_,
                              hourglass_ + stabilization_,
                              kick_.external_work,  kick_.boundary_work, kick_.momentum[0],
                              kick_.momentum[1],    kick_.momentum[2],   filter_work_, bond_,
                              contact.total,        contact.friction,    contact.stored, contact.damping};
    double       g[14];
    dealii::Utilities::MPI::sum(dealii::ArrayView<const double>(local, 14), comm, dealii::ArrayView<double>(g, 14));
    Totals t;
    // The contact energy (stored in the penalty springs plus dissipated by friction) counts as
    // internal energy.
    t.kinetic = g[0], t.internal = g[1] + g[2] + g[10], t.hourglass = g[2], t.external = g[3], t.boundary = g[4];
    t.filter = g[8], t.bond = g[9], t.conversion = conversion_;
    t.momentum[0] = g[5], t.momentum[1] = g[6], t.momentum[2] = g[7];
    t.contact = g[10], t.friction = g[11], t.stored = g[12], t.damping = g[13];
    const double reference = std::max(initial_ + std::abs(t.external) + std::abs(t.boundary) + std::abs(t.filter) +
                                        std::abs(conversion_) + std::abs(t.bond),
                                      std::max(t.kinetic, floor_));
    error_ = reference > 0 ? (t.kinetic + t.internal - initial_ - t.external - t.boundary - t.filter - conversion_ -
                              t.bond) /
                               reference :
                             0.;
    max_error_ = std::max(max_error_, std::abs(error_));
    t.error    = error_;
    return t;
  }

  std::vector<double>
  EnergyBalance::rank_values() const
  {
    return {internal_,
            hourglass_,
            stabilization_,
            filter_work_,
            conversion_elastic_,
            bond_,
            kick_.kinetic,
            kick_.momentum[0],
            kick_.momentum[1],
            kick_.momentum[2],
            kick_.external_work,
            kick_.boundary_work,
            kick_.pending_external,
            kick_.pending_boundary};
  }

  void
  EnergyBalance::restore_rank_values(const std::vector<double> &s, const bool same_partition,
                                     const double stabilization)
  {
    if (s.size() != n_rank_values)
      throw std::runtime_error("wrong number of energy values");
    internal_ = s[0], hourglass_ = s[1];
    stabilization_ = same_partition ? s[2] : stabilization;
    filter_work_ = s[3], conversion_elastic_ = s[4], bond_ = s[5];
    kick_.kinetic = s[6];
    for (unsigned int c = 0; c < 3; ++c)
      kick_.momentum[c] = s[7 + c];
    kick_.external_work = s[10], kick_.boundary_work = s[11];
    kick_.pending_external = s[12], kick_.pending_boundary = s[13];
  }
} // namespace shard
