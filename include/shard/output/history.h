// SPDX-License-Identifier: LGPL-2.1-or-later
/**
 * @file history.h
 * @brief history.csv: one row per record, header and rows from one column list.
 * @ingroup output
 */
#pragma once

#include <fstream>
#include <string>
#include <vector>

namespace shard::output
{
  /**
   * @brief The history table of a run (rank 0 writes it).
   *
   * A row is a list of named columns; the names of the first row make the header, so header
   * and rows cannot drift apart. Reals are written with 17 significant digits (`%.16e`),
   * counts as integers. Rows recorded before the file is opened (step 0, which must pass its
   * checks before the run owns its output directory) wait in memory.
   */
  class HistoryTable
  {
  public:
    /// One cell of a row.
    struct Column
    {
      std::string name;
      double      value   = 0;
      /// Written as an unsigned integer (the value is a count below 2^53).
      bool integer = false;
    };
    using Row = std::vector<Column>;

    /// Adds a row: written if the file is open, kept until open() otherwise. The first row fixes the columns.
    void
    add(const Row &row);

    /**
     * @brief Opens @p path; a new table gets the header and the rows kept so far, an @p append
     * one (restart) continues after the rows already in the file.
     */
    void
    open(const std::string &path, bool append);

    /// Whether the file is open.
    bool
    is_open() const
    {
      return file_.is_open();
    }

    /// Writes what the stream holds (before a checkpoint measures the file; at progress lines).
    void
    flush()
    {
      file_.flush();
    }

    /// Closes the file at the end of the run.
    void
    close()
    {
      file_.close();
    }

    /// The header line of @p row (without the newline).
    static std::string
    header(const Row &row);

    /// The text of @p row (without the newline).
    static std::string
    format(const Row &row);

    /// The index of the first column of @p row whose value is not finite, or -1.
    static int
    first_non_finite(const Row &row);

  private:
    std::ofstream file_;
    std::string   header_;
    std::string   pending_;
  };
} // namespace shard::output
