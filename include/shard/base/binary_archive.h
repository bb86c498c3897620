// SPDX-License-Identifier: LGPL-2.1-or-later
/**
 * @file binary_archive.h
 * @brief A minimal binary archive for checkpoints: arithmetic values, strings, std::array,
 *        std::pair and (nested) std::vector, in the machine's byte order.
 * @ingroup base
 */
#pragma once

#include <array>
#include <cstdint>
#include <cstring>
#include <stdexcept>
#include <string>
#include <type_traits>
#include <utility>
#include <vector>

namespace shard::base
{
  /// The 64-bit FNV-1a hash of @p data (checkpoint files and the tables they continue).
  inline std::uint64_t
  fnv1a(const std::string &data)
  {
    std::uint64_t h = 14695981039346656037ull;
    for (const unsigned char c : data)
      {
        h ^= c;
        h *= 1099511628211ull;
      }
    return h;
  }

  /**
   * @brief Appends values to a byte string. A vector is its length (64 bit) followed by its
   * elements; a tag (a short string) before each section lets the reader detect a file that
   * does not match the code that reads it.
   */
  class BinaryWriter
  {
  public:
    /// Arithmetic values and enums: their bytes.
    template <typename T>
    std::enable_if_t<std::is_arithmetic_v<T> || std::is_enum_v<T>>
    put(const T &x)
    {
      buffer_.append(reinterpret_cast<const char *>(&x), sizeof(T));
    }

    /// A string: its length, then its characters.
    void
    put(const std::string &s)
    {
      put(static_cast<std::uint64_t>(s.size()));
      buffer_.append(s);
    }

    /// A fixed array, element by element.
    template <typename T, std::size_t N>
    void
    put(const std::array<T, N> &a)
    {
      for (const auto &x : a)
        put(x);
    }

    /// A pair: first, then second.
    template <typename A, typename B>
    void
    put(const std::pair<A, B> &p)
    {
      put(p.first);
      put(p.second);
    }

    /// A vector: its length, then its elements (contiguous bytes for arithmetic types).
    template <typename T>
    void
    put(const std::vector<T> &v)
    {
      put(static_cast<std::uint64_t>(v.size()));
      if constexpr (std::is_arithmetic_v<T> && !std::is_same_v<T, bool>)
        buffer_.append(reinterpret_cast<const char *>(v.data()), v.size() * sizeof(T));
      else
        for (const auto &x : v)
          put(static_cast<const T &>(x));
    }

    /// The bytes written so far.
    const std::string &
    str() const
    {
      return buffer_;
    }

  private:
    std::string buffer_;
  };

  /**
   * @brief Reads what BinaryWriter wrote, in the same order.
   * @throws std::runtime_error when the data end early or a tag does not match.
   */
  class BinaryReader
  {
  public:
    /// Reads from @p data, which must outlive the reader.
    explicit BinaryReader(const std::string &data)
      : data_(data)
    {}

    /// Arithmetic values and enums.
    template <typename T>
    std::enable_if_t<std::is_arithmetic_v<T> || std::is_enum_v<T>>
    get(T &x)
    {
      need(sizeof(T));
      std::memcpy(&x, data_.data() + pos_, sizeof(T));
      pos_ += sizeof(T);
    }

    /// A string.
    void
    get(std::string &s)
    {
      const std::uint64_t n = length();
      need(n);
      s.assign(data_.data() + pos_, n);
      pos_ += n;
    }

    /// A fixed array.
    template <typename T, std::size_t N>
    void
    get(std::array<T, N> &a)
    {
      for (auto &x : a)
        get(x);
    }

    /// A pair.
    template <typename A, typename B>
    void
    get(std::pair<A, B> &p)
    {
      get(p.first);
      get(p.second);
    }

    /// A vector (resized to the stored length).
    template <typename T>
    void
    get(std::vector<T> &v)
    {
      const std::uint64_t n = length();
      if constexpr (std::is_arithmetic_v<T> && !std::is_same_v<T, bool>)
        {
          need(n * sizeof(T));
          v.resize(n);
          std::memcpy(v.data(), data_.data() + pos_, n * sizeof(T));
          pos_ += n * sizeof(T);
        }
      else if constexpr (std::is_same_v<T, bool>)
        {
          v.resize(n);
          for (std::uint64_t i = 0; i < n; ++i)
            {
              bool b;
              get(b);
              v[i] = b;
            }
        }
      else
        {
          v.resize(n);
          for (auto &x : v)
            get(x);
        }
    }

    /// A value returned rather than passed.
    template <typename T>
    T
    get()
    {
      T x{};
      get(x);
      return x;
    }

    /// Reads a tag and checks that it is @p tag.
    void
    expect(const std::string &tag)
    {
      std::string s;
      get(s);
      if (s != tag)
        throw std::runtime_error("expected section '" + tag + "', found '" + s.substr(0, 40) + "'");
    }

    /// Whether everything was read.
    bool
    at_end() const
    {
      return pos_ == data_.size();
    }

  private:
    const std::string &data_;
    std::size_t        pos_ = 0;

    std::uint64_t
    length()
    {
      std::uint64_t n = 0;
      get(n);
      if (n > data_.size())
        throw std::runtime_error("stored length " + std::to_string(n) + " exceeds the data");
      return n;
    }

    void
    need(const std::size_t n) const
    {
      if (n > data_.size() - pos_)
        throw std::runtime_error("the data end early (truncated or corrupt file)");
    }
  };
} // namespace shard::base
