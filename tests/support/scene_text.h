// SPDX-License-Identifier: LGPL-2.1-or-later
/**
 * @file scene_text.h
 * @brief Parameter-file text for the unit tests that set up a small model: the elastic steel
 *        they share, a box body, and a .prm written to the temporary directory and read back.
 */
#pragma once

#include <shard/base/parameters.h>

#include <filesystem>
#include <fstream>
#include <string>

#include <unistd.h>

namespace shard::test_support
{
  /// `C - Materials` with one material `steel`: elastic, density 7850 kg/m^3, E 200 GPa, nu 0.3.
  inline std::string
  elastic_steel()
  {
    return "subsection C - Materials\n set material names = steel\n subsection steel\n"
           "  set model = elastic\n  set density = 7850\n  set young's modulus = 200e9\n"
           "  set poisson's ratio = 0.3\n end\nend\n";
  }

  /// `B - Mesh` with one body `cube` of steel: the unit cube, refined @p refinement times.
  inline std::string
  unit_cube(const unsigned int refinement)
  {
    return "subsection B - Mesh\n set body names = cube\n subsection cube\n  set shape = box\n"
           "  set lower corner = 0, 0, 0\n  set upper corner = 1, 1, 1\n  set refinement = " +
           std::to_string(refinement) + "\n  set material = steel\n end\nend\n";
  }

  /**
   * Writes @p text to a file in the temporary directory, reads it as a parameter file and
   * removes the file. The file name is @p name with the process id in front: ctest runs the
   * tests of one program as concurrent processes, and a shared name let one test read the scene
   * another was writing (HexForce failed that way in CI). Within a process the file is gone
   * before the next call.
   */
  inline base::PrmSource
  scene_source(const std::string &name, const std::string &text)
  {
    const auto path = std::filesystem::temp_directory_path() / (std::to_string(::getpid()) + "_" + name);
    {
      std::ofstream out(path);
      out << text;
    }
    base::PrmSource source(path.string());
    std::filesystem::remove(path);
    return source;
  }
} // namespace shard::test_support
