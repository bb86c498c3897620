// SPDX-License-Identifier: LGPL-2.1-or-later
/**
 * @file energy_balance.h
 * @brief The energy accounts of a run: accumulators, their reduction over ranks, the energy
 *        error and its limit, and their checkpoint.
 * @ingroup simulation
 */
#pragma once

#include <shard/time/central_difference.h>

#include <mpi.h>

#include <vector>

namespace shard
{
  /// The contact terms of this rank (J), as Contact reports them.
  struct ContactEnergies
  {
    /// Stored in the penalty springs plus dissipated (friction, dashpots, lost).
    double total = 0;
    /// Dissipated by friction.
    double friction = 0;
    /// Stored in the springs now.
    double stored = 0;
    /// Dissipated by contact damping.
    double damping = 0;
  };

  /**
   * @brief The energy balance of the explicit step (doc/manual/time_loop.md, "Energy").
   *
   * Each rank accumulates its share of every term; reduce() sums them over the ranks and forms
   * the error
   *
   *     e = (K + U - K0 - W_ext - W_bc - W_filter - E_conversion - E_bond) / R,
   *     R = max(K0 + |W_ext| + |W_bc| + |W_filter| + |E_conversion| + |E_bond|, K, floor),
   *
   * where U is the internal energy (stress work, elastic energy changed by conversions, FE
   * hourglass work, particle stabilization energy, and the contact energy) and floor = 1e-14 M
   * c^2 keeps a model at rest from reporting round-off as an error of 1. The kinetic energy,
   * momentum and the work of loads and kinematic conditions come from the kick
   * (time::LocalBalance, product form). Conversion energy is booked on every rank alike (it is a
   * global sum when it is booked).
   */
  class EnergyBalance
  {
  public:
    /// The sums over all ranks of one record (J; momentum in kg m/s).
    struct Totals
    {
      double kinetic = 0;
      /// Internal energy including the contact energy (the `internal_energy` column).
      double internal = 0;
      /// FE hourglass work plus particle stabilization energy (`hourglass_energy`).
      double hourglass = 0;
      double external = 0, boundary = 0, filter = 0, conversion = 0, bond = 0;
      double momentum[3] = {0, 0, 0};
      /// Contact terms (ContactEnergies summed).
      double contact = 0, friction = 0, stored = 0, damping = 0;
      /// The relative energy error e of this record.
      double error = 0;

      /// Contact energy neither stored nor dissipated by friction or damping (J).
      double
      contact_lost() const
      {
        return contact - friction - stored - damping;
      }
    };

    /// The initial kinetic energy K0 (J), from the input velocity before the conditions at t = 0.
    void
    set_initial_kinetic(const double initial_kinetic)
    {
      initial_ = initial_kinetic;
    }

    /// The floor of the reference, 1e-14 M c^2 (J).
    void
    set_floor(const double floor)
    {
      floor_ = floor;
    }

    /// The terms the kick updates: kinetic energy, momentum, work of loads and conditions.
    time::LocalBalance &
    kick_terms()
    {
      return kick_;
    }

    /// Adds stress work of this rank (J).
    void
    add_internal(const double w)
    {
      internal_ += w;
    }

    /// Adds FE hourglass work of this rank (J).
    void
    add_hourglass(const double w)
    {
      hourglass_ += w;
    }

    /// The particle stabilization energy of this rank now (J; a state, not an increment).
    void
    set_stabilization(const double w)
    {
      stabilization_ = w;
    }

    /// The particle stabilization energy of this rank (J).
    double
    stabilization() const
    {
      return stabilization_;
    }

    /// Adds work of the R1 filter on this rank (J).
    void
    add_filter_work(const double w)
    {
      filter_work_ += w;
    }

    /**
     * @brief Books a change of the particle force by broken bonds as bond energy: the kick's
     * product-form kinetic energy sees dt/2 (f_new - f_old) . v^{n+1/2} at once, and the
     * stabilization energy jumps from its old value to @p new_stabilization.
     * @param df the force change (owned entries are summed in order)
     * @param v  the velocity v^{n+1/2}
     */
    template <typename VectorType>
    void
    book_bond_change(const VectorType &df, const VectorType &v, const double dt, const double new_stabilization)
    {
      // A local sum in one order (the member would be reloaded at every term).
      double bond = bond_;
      for (unsigned int i = 0; i < df.locally_owned_size(); ++i)
        bond += 0.5 * dt * df.local_element(i) * v.local_element(i);
      bond_ = bond;
      bond_ += new_stabilization - stabilization_;
      stabilization_ = new_stabilization;
    }

    /**
     * @brief Books a conversion: @p change (summed over ranks, the same on every rank) is a
     * source; @p elastic_on_this_rank is its elastic part, added to this rank's internal
     * energy.
     */
    void
    book_conversion(const double change, const double elastic_on_this_rank)
    {
      conversion_elastic_ += elastic_on_this_rank;
      conversion_ += change;
    }

    /// The conversion energy of the run so far (J, all ranks).
    double
    conversion_energy() const
    {
      return conversion_;
    }

    /**
     * @brief Sums every term over the ranks and forms the error (one reduction); updates error()
     * and max_error(). @note Collective.
     */
    Totals
    reduce(const ContactEnergies &contact, MPI_Comm comm);

    /// The error of the last reduce().
    double
    error() const
    {
      return error_;
    }

    /// The largest |error| of the run so far.
    double
    max_error() const
    {
      return max_error_;
    }

    /// K0 (J).
    double
    initial_kinetic() const
    {
      return initial_;
    }

    /// This rank's accumulators for a checkpoint (the last value is not summable).
    std::vector<double>
    rank_values() const;

    /**
     * @brief Restores this rank's accumulators from rank_values() of a checkpoint (at another
     * rank count: the sums on rank 0, zeros elsewhere).
     * @param stabilization this rank's stabilization energy of the restored state (used at
     *        another rank count, where the checkpointed one belongs to another partition)
     * @param same_partition whether the checkpoint was written at this rank count
     */
    void
    restore_rank_values(const std::vector<double> &values, bool same_partition, double stabilization);

    /// The number of rank_values().
    static constexpr unsigned int n_rank_values = 14;

    /// The values that are the same on every rank, for a checkpoint; @p io is put or get.
    template <typename IO>
    void
    serialize_global(IO &&io)
    {
      io(conversion_), io(initial_), io(error_), io(max_error_);
    }

  private:
    time::LocalBalance kick_;
    double             internal_ = 0, hourglass_ = 0, stabilization_ = 0, filter_work_ = 0;
    /// Elastic part of the conversion energy on this rank (J), in the internal energy.
    double conversion_elastic_ = 0;
    /// Jump of the stabilization energy and kick change when bonds break, this rank (J).
    double bond_ = 0;
    /// Energy changed by conversions, summed over ranks (J).
    double conversion_ = 0;
    double initial_ = 0, floor_ = 0, error_ = 0, max_error_ = 0;
  };
} // namespace shard
