// SPDX-License-Identifier: LGPL-2.1-or-later
#include <shard/output/history.h>

#include <cmath>
#include <cstdio>

namespace shard::output
{
  std::string
  HistoryTable::header(const Row &row)
  {
    std::string line;
    for (std::size_t k = 0; k < row.size(); ++k)
      line += (k ? "," : "") + row[k].name;
    return line;
  }

  std::string
  HistoryTable::format(const Row &row)
  {
    std::string line;
    char        cell[64];
    for (std::size_t k = 0; k < row.size(); ++k)
      {
        if (row[k].integer)
          std::snprintf(cell, sizeof(cell), "%s%llu", k ? "," : "", static_cast<unsigned long long>(row[k].value));
        else
          std::snprintf(cell, sizeof(cell), "%s%.16e", k ? "," : "", row[k].value);
        line += cell;
      }
    return line;
  }

  int
  HistoryTable::first_non_finite(const Row &row)
  {
    for (std::size_t k = 0; k < row.size(); ++k)
      if (!std::isfinite(row[k].value))
        return static_cast<int>(k);
    return -1;
  }

  void
  HistoryTable::add(const Row &row)
  {
    if (header_.empty())
      header_ = header(row);
    const std::string line = format(row) + "\n";
    if (file_.is_open())
      file_ << line;
    else
      pending_ += line;
  }

  void
  HistoryTable::open(const std::string &path, const bool append)
  {
    if (append)
      file_.open(path, std::ios::app);
    else
      {
        file_.open(path);
        file_ << header_ << "\n" << pending_;
      }
    pending_.clear();
  }
} // namespace shard::output
