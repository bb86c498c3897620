// SPDX-License-Identifier: LGPL-2.1-or-later
// EnergyBalance (simulation/energy_balance.h): the error against its closed form, the bond and
// conversion bookings, the floor, and the checkpoint round trip. One rank (MPI_COMM_SELF).
#include <shard/simulation/energy_balance.h>

#include <gtest/gtest.h>

#include <cmath>
#include <vector>

namespace
{
  using namespace shard;

  /// The two members of a distributed vector book_bond_change() uses.
  struct Plain
  {
    std::vector<double> x;
    unsigned int
    locally_owned_size() const
    {
      return x.size();
    }
    double
    local_element(const unsigned int i) const
    {
      return x[i];
    }
  };

  /// A balance with every term set (J): K0 100, K 60, stress work 30, hourglass 5,
  /// stabilization 3, filter -2, external 4, boundary -6, conversion 1.5 (elastic 0.5).
  EnergyBalance
  filled()
  {
    EnergyBalance e;
    e.set_initial_kinetic(100);
    e.set_floor(1e-12);
    e.kick_terms().kinetic       = 60;
    e.kick_terms().external_work = 4;
    e.kick_terms().boundary_work = -6;
    e.kick_terms().momentum[1]   = 7;
    e.add_internal(30);
    e.add_hourglass(5);
    e.set_stabilization(3);
    e.add_filter_work(-2);
    e.book_conversion(1.5, 0.5);
    return e;
  }
} // namespace

TEST(EnergyBalance, ErrorIsTheClosedForm)
{
  auto       e = filled();
  const auto t = e.reduce({2, 0.5, 1, 0.25}, MPI_COMM_SELF);
  // U = 30 + 0.5 (conversion elastic) + 5 + 3 (hourglass column) + 2 (contact) = 40.5.
  EXPECT_DOUBLE_EQ(t.internal, 40.5);
  EXPECT_DOUBLE_EQ(t.hourglass, 8);
  EXPECT_DOUBLE_EQ(t.momentum[1], 7);
  EXPECT_DOUBLE_EQ(t.contact_lost(), 2 - 0.5 - 1 - 0.25);
  // e = (K + U - K0 - W_ext - W_bc - W_f - E_conv - E_bond) / R,
  // R = max(K0 + |W_ext| + |W_bc| + |W_f| + |E_conv| + |E_bond|, K) = 100 + 4 + 6 + 2 + 1.5 = 113.5.
  const double expected = (60 + 40.5 - 100 - 4 - (-6) - (-2) - 1.5 - 0) / 113.5;
  EXPECT_DOUBLE_EQ(t.error, expected);
  EXPECT_DOUBLE_EQ(e.error(), expected);
  EXPECT_DOUBLE_EQ(e.max_error(), std::abs(expected));
}

TEST(EnergyBalance, MaxErrorKeepsTheLargestMagnitude)
{
  auto e = filled();
  e.reduce({}, MPI_COMM_SELF);
  const double first = std::abs(e.error());
  e.add_internal(-1000); // a large negative error
  e.reduce({}, MPI_COMM_SELF);
  EXPECT_GT(e.max_error(), first);
  EXPECT_DOUBLE_EQ(e.max_error(), std::abs(e.error()));
  e.add_internal(1000); // back: the maximum stays
  e.reduce({}, MPI_COMM_SELF);
  EXPECT_GT(e.max_error(), std::abs(e.error()));
}

TEST(EnergyBalance, FloorKeepsRoundOffAtRestSmall)
{
  EnergyBalance e;
  e.set_floor(1e-10);
  e.add_internal(1e-20); // round-off of a model at rest
  e.reduce({}, MPI_COMM_SELF);
  EXPECT_DOUBLE_EQ(e.error(), 1e-20 / 1e-10);
  EnergyBalance none; // no floor, nothing moves: no reference, no error
  none.reduce({}, MPI_COMM_SELF);
  EXPECT_EQ(none.error(), 0.);
}

TEST(EnergyBalance, BondChangeBooksTheKickShareAndTheStabilizationJump)
{
  // Before the break the balance is closed: K0 = 3 J sits as stabilization energy.
  EnergyBalance e;
  e.set_initial_kinetic(3);
  e.set_stabilization(3);
  EXPECT_EQ(e.reduce({}, MPI_COMM_SELF).error, 0.);
  const Plain df{{1, 2, 3}}, v{{4, 5, 6}};
  e.book_bond_change(df, v, 0.1, 5);
  // dt/2 df . v = 0.05 x 32 = 1.6, plus the jump 5 - 3.
  EXPECT_DOUBLE_EQ(e.reduce({}, MPI_COMM_SELF).bond, 1.6 + 2);
  EXPECT_DOUBLE_EQ(e.stabilization(), 5);
  // The kick then gains the 1.6 J the refreshed force does over the half step: the source
  // booked is exactly what appeared, and the balance stays closed.
  e.kick_terms().kinetic = 1.6;
  EXPECT_NEAR(e.reduce({}, MPI_COMM_SELF).error, 0., 1e-15);
}

TEST(EnergyBalance, CheckpointRoundTrip)
{
  auto e = filled();
  e.reduce({}, MPI_COMM_SELF);
  std::vector<double> global;
  e.serialize_global([&](double &x) { global.push_back(x); });
  const auto values = e.rank_values();
  ASSERT_EQ(values.size(), EnergyBalance::n_rank_values);

  EnergyBalance r;
  r.set_floor(1e-12);
  std::size_t k = 0;
  r.serialize_global([&](double &x) { x = global[k++]; });
  r.restore_rank_values(values, true, -1);
  EXPECT_EQ(r.rank_values(), values);
  EXPECT_EQ(r.initial_kinetic(), 100);
  EXPECT_EQ(r.conversion_energy(), 1.5);
  EXPECT_EQ(r.max_error(), e.max_error());
  EXPECT_EQ(r.reduce({}, MPI_COMM_SELF).error, filled().reduce({}, MPI_COMM_SELF).error);

  // At another rank count the stabilization energy is this partition's, not the checkpoint's.
  EnergyBalance other;
  other.restore_rank_values(values, false, 42);
  EXPECT_EQ(other.stabilization(), 42);
  EXPECT_THROW(other.restore_rank_values({1, 2}, true, 0), std::runtime_error);
}
