// SPDX-License-Identifier: LGPL-2.1-or-later
// One GoogleTest main for serial and MPI tests: MPI is initialised once, only rank 0 prints,
// and a failure on any rank fails the run on every rank.
#include <deal.II/base/mpi.h>

#include <gtest/gtest.h>

int
main(int argc, char **argv)
{
  dealii::Utilities::MPI::MPI_InitFinalize mpi(argc, argv, 1);
  ::testing::InitGoogleTest(&argc, argv);
  const unsigned int rank = dealii::Utilities::MPI::this_mpi_process(MPI_COMM_WORLD);
  if (rank != 0)
    {
      auto &listeners = ::testing::UnitTest::GetInstance()->listeners();
      delete listeners.Release(listeners.default_result_printer());
    }
  const int local  = RUN_ALL_TESTS();
  const int global = dealii::Utilities::MPI::max(local, MPI_COMM_WORLD);
  return global;
}
