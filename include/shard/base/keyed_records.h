// SPDX-License-Identifier: LGPL-2.1-or-later
/**
 * @file keyed_records.h
 * @brief Records of doubles by a key that does not depend on the partition (a checkpoint key of
 * a node, a cell index): how a component writes its per-node, per-element or per-particle
 * state for a restart at any rank count, and finds it again among the records of every rank.
 * @ingroup base
 */
#pragma once

#include <cstddef>
#include <stdexcept>
#include <string>
#include <unordered_map>
#include <utility>
#include <vector>

namespace shard::base
{
  /// Records of variable length, each under a key (one rank's part of a checkpoint).
  struct KeyedRecords
  {
    std::vector<unsigned long long> keys;
    /// Start of record k in values is offsets[k]; offsets has one entry more than keys.
    std::vector<unsigned long long> offsets{0};
    std::vector<double>             values;

    /// Appends the record [@p begin, @p end) under @p key.
    void
    add(const unsigned long long key, const double *begin, const double *end)
    {
      keys.push_back(key);
      values.insert(values.end(), begin, end);
      offsets.push_back(values.size());
    }

    /// One field list for writing and reading: @p io(x) for every member.
    template <typename IO>
    void
    serialize(IO &&io)
    {
      io(keys), io(offsets), io(values);
    }
  };

  /// Finds a record by its key among the records of every rank of a checkpoint.
  class KeyedLookup
  {
  public:
    /// A record: its first value and its length.
    struct Record
    {
      const double *values = nullptr;
      std::size_t   size   = 0;
    };

    /// Indexes @p parts (one per rank that wrote them); they must outlive the lookup.
    explicit KeyedLookup(const std::vector<const KeyedRecords *> &parts)
    {
      for (const auto *part : parts)
        {
          if (part->offsets.size() != part->keys.size() + 1 || part->offsets.back() != part->values.size())
            throw std::runtime_error("a keyed record list of the checkpoint is inconsistent");
          for (std::size_t k = 0; k < part->keys.size(); ++k)
            at_[part->keys[k]] = Record{part->values.data() + part->offsets[k],
                                        static_cast<std::size_t>(part->offsets[k + 1] - part->offsets[k])};
        }
    }

    /// The record of @p key; throws std::runtime_error "<what> is missing" if there is none.
    Record
    find(const unsigned long long key, const std::string &what) const
    {
      const auto it = at_.find(key);
      if (it == at_.end())
        throw std::runtime_error(what + " is missing");
      return it->second;
    }

  private:
    std::unordered_map<unsigned long long, Record> at_;
  };
} // namespace shard::base
