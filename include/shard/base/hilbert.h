// SPDX-License-Identifier: LGPL-2.1-or-later
/**
 * @file hilbert.h
 * @brief The index of a point of a 3-D integer grid along the Hilbert curve, for ordering cells
 *        before they are cut into the ranks' parts.
 * @ingroup base
 */
#pragma once

#include <array>
#include <cstdint>

namespace shard::base
{
  /**
   * @brief Position of the grid point @p x (each coordinate below 2^@p bits, @p bits at most 21)
   * along the 3-D Hilbert curve of order @p bits: a number below 2^(3 bits). Consecutive
   * numbers belong to grid points one step apart, so a contiguous range of numbers is a compact
   * piece of space.
   *
   * The transform of J. Skilling, "Programming the Hilbert curve", AIP Conf. Proc. 707 (2004)
   * 381: the coordinates are turned into the "transposed" index, bit plane by bit plane from
   * the top (an inversion or an exchange of the lower bits per plane, then a Gray code), and the
   * bits of the three transposed words are interleaved. O(bits) operations per point, no tables.
   */
  inline std::uint64_t
  hilbert_index(std::array<std::uint32_t, 3> x, const unsigned int bits)
  {
    if (bits == 0)
      return 0;
    const std::uint32_t top = std::uint32_t(1) << (bits - 1);
    // Undo the rotations and reflections of the sub-cubes, from the largest down.
    for (std::uint32_t q = top; q > 1; q >>= 1)
      {
        const std::uint32_t p = q - 1;
        for (unsigned int i = 0; i < 3; ++i)
          if (x[i] & q)
            x[0] ^= p; // invert the lower bits of x[0]
          else
            {
              const std::uint32_t t = (x[0] ^ x[i]) & p; // exchange the lower bits of x[0] and x[i]
              x[0] ^= t;
              x[i] ^= t;
            }
      }
    // Gray encoding.
    x[1] ^= x[0];
    x[2] ^= x[1];
    std::uint32_t t = 0;
    for (std::uint32_t q = top; q > 1; q >>= 1)
      if (x[2] & q)
        t ^= q - 1;
    for (unsigned int i = 0; i < 3; ++i)
      x[i] ^= t;
    // Interleave: the index's bit triples, from the top, are (x[0], x[1], x[2]) of one plane.
    std::uint64_t h = 0;
    for (int b = static_cast<int>(bits) - 1; b >= 0; --b)
      for (unsigned int i = 0; i < 3; ++i)
        h = (h << 1) | ((x[i] >> b) & 1u);
    return h;
  }
} // namespace shard::base
