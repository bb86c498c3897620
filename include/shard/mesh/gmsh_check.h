// SPDX-License-Identifier: LGPL-2.1-or-later
/**
 * @file gmsh_check.h
 * @brief Structural check of a Gmsh ASCII .msh file before deal.II's GridIn reads it.
 * @ingroup mesh
 */
#pragma once

#include <istream>
#include <stdexcept>
#include <string>

namespace shard::mesh
{
  /**
   * @brief What check_gmsh() found in a file it accepted.
   */
  struct GmshSummary
  {
    /// Nodes in `$Nodes`.
    unsigned long long n_nodes = 0;
    /// Hexahedra (Gmsh element type 5) in `$Elements`: the cells GridIn will create.
    unsigned long long n_hexahedra = 0;
    /// All elements in `$Elements` (hexahedra and boundary lines, quadrilaterals and points).
    unsigned long long n_elements = 0;
    /// Format version of the `$MeshFormat` line: 2.0, 2.1, 2.2 or 4.1.
    double version = 0;
  };

  /**
   * @brief A file refused by check_gmsh(). what() is one line of printable ASCII,
   * `line N: <problem>`; a quoted excerpt of the file is cut to 40 characters and every byte
   * outside 0x20-0x7e in it is written `\xHH`.
   */
  class GmshError : public std::invalid_argument
  {
  public:
    /// @param line 1-based line of the file; @param problem the message after `line N: `.
    GmshError(unsigned long long line, const std::string &problem);

    /// The 1-based line the message is about.
    unsigned long long
    line() const noexcept
    {
      return line_;
    }

    /// The message without the `line N: ` prefix.
    std::string
    problem() const;

  private:
    unsigned long long line_;
  };

  /**
   * @brief Reads the Gmsh ASCII mesh in @p in once, line by line, and throws GmshError at the
   * first line that deal.II 9.4's `GridIn<3>::read_msh(std::istream &)` could not read into a
   * hexahedral mesh, or could read only by allocating without bound, looping or reading out of
   * bounds. A file accepted here has counts that agree with its content.
   *
   * What is checked:
   * - every byte is text: no byte below 0x20 except tab, CR and LF, and no 0x7f (bytes of 0x80
   *   and above, e.g. UTF-8 in physical names, are allowed); lines are at most 8 MiB;
   * - `$MeshFormat` first, then `version file-type data-size` with version 2.0, 2.1, 2.2 or 4.1,
   *   file-type 0 (ASCII; binary files are refused) and data-size 8, then `$EndMeshFormat`;
   * - every `$Section` is ended by `$EndSection`; between `$EndMeshFormat` and `$Nodes` only
   *   `$PhysicalNames`, then (version 4.1) `$Entities` and `$PartitionedEntities`, in this
   *   order, as deal.II reads them; `$Elements` directly after `$Nodes`; other sections after
   *   `$Elements` are skipped; each of `$MeshFormat`, `$Nodes`, `$Elements` appears once;
   * - version 2.x: `$Nodes` count, then exactly that many `tag x y z` lines; `$Elements`
   *   count, then lines `tag type ntags tag... node...` with the number of nodes of the type;
   * - version 4.1: the `$Entities` counts and lines (at most one physical tag per entity, as
   *   deal.II requires); the `$Nodes` header `blocks nodes min-tag max-tag`, block headers
   *   `entity-dim entity-tag parametric n`, n tag lines, n coordinate lines, blocks and nodes
   *   adding up to the header; the same for `$Elements` with lines `tag node...`;
   * - integers are integers in the range deal.II reads them into (tags 1..2147483647), numbers
   *   are finite (`1e400` is refused), node tags are distinct and within the header's range,
   *   every node an element names exists;
   * - element types: hexahedra (5) and, on the boundary, lines (1), quadrilaterals (3) and
   *   points (15); triangles, tetrahedra, prisms, pyramids and second-order types are refused
   *   with the type named; the physical tag of a line or quadrilateral becomes a deal.II
   *   boundary id and must be 0..254; at least one hexahedron must be present.
   *
   * Not checked: geometry (a zero-volume or inverted hexahedron is valid here) and whether
   * boundary elements are faces of the hexahedra.
   *
   * Memory is bounded by the size of the file (at most 20 bytes per node and one line of text);
   * no count read from the file sizes an allocation. The stream is read to its end.
   *
   * @param in a stream opened by the caller; a stream that has already failed, a directory and
   *        an empty stream are refused.
   * @return the counts of the accepted file.
   * @throws GmshError naming the line and the problem.
   */
  GmshSummary
  check_gmsh(std::istream &in);
} // namespace shard::mesh
