// SPDX-License-Identifier: LGPL-2.1-or-later
// HistoryTable (output/history.h): header and rows from one column list, exact reals, counts
// as integers, rows kept until the file opens, append on restart, non-finite columns.
#include <shard/output/history.h>

#include <unistd.h>

#include <gtest/gtest.h>

#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <limits>
#include <sstream>
#include <string>

namespace
{
  using shard::output::HistoryTable;

  std::string
  read(const std::string &path)
  {
    std::ifstream     in(path);
    std::stringstream s;
    s << in.rdbuf();
    return s.str();
  }

  HistoryTable::Row
  row(const double t, const unsigned long long step, const double e)
  {
    return {{"time", t}, {"step", double(step), true}, {"energy", e}};
  }
} // namespace

TEST(HistoryTable, HeaderAndRowFromOneList)
{
  const auto r = row(0.1, 12, -2.5);
  EXPECT_EQ(HistoryTable::header(r), "time,step,energy");
  EXPECT_EQ(HistoryTable::format(r), "1.0000000000000001e-01,12,-2.5000000000000000e+00");
}

TEST(HistoryTable, RealsRoundTripExactly)
{
  for (const double x : {1. / 3., 2.718281828459045e-300, -6.02214076e23, 5e-324})
    {
      const std::string text = HistoryTable::format({{"x", x}});
      EXPECT_EQ(std::strtod(text.c_str(), nullptr), x) << text;
    }
  // A count up to 2^53 is written exactly as an integer.
  EXPECT_EQ(HistoryTable::format({{"n", 9007199254740992., true}}), "9007199254740992");
}

TEST(HistoryTable, FirstNonFiniteColumn)
{
  EXPECT_EQ(HistoryTable::first_non_finite(row(1, 2, 3)), -1);
  EXPECT_EQ(HistoryTable::first_non_finite(row(1, 2, std::nan(""))), 2);
  EXPECT_EQ(HistoryTable::first_non_finite(row(std::numeric_limits<double>::infinity(), 2, std::nan(""))), 0);
}

TEST(HistoryTable, RowsWaitForTheFileAndRestartAppends)
{
  const auto dir  = std::filesystem::temp_directory_path() / ("shard_history_test_" + std::to_string(::getpid()));
  const auto path = (dir / "history.csv").string();
  std::filesystem::create_directories(dir);
  {
    HistoryTable h;
    h.add(row(0, 0, 1)); // step 0, before the run owns its directory
    EXPECT_FALSE(h.is_open());
    h.open(path, false);
    h.add(row(1e-6, 1, 2));
    h.close();
  }
  const std::string header = "time,step,energy\n";
  const std::string r0 = HistoryTable::format(row(0, 0, 1)) + "\n", r1 = HistoryTable::format(row(1e-6, 1, 2)) + "\n";
  EXPECT_EQ(read(path), header + r0 + r1);
  {
    HistoryTable h; // a restart: no header, rows appended
    h.open(path, true);
    h.add(row(2e-6, 2, 3));
    h.close();
  }
  EXPECT_EQ(read(path), header + r0 + r1 + HistoryTable::format(row(2e-6, 2, 3)) + "\n");
  std::filesystem::remove_all(dir);
}
