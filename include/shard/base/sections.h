// SPDX-License-Identifier: LGPL-2.1-or-later
/**
 * @file sections.h
 * @brief The names of the parameter subsections, defined once (doc/manual/user_guide.md,
 *        "Parameters"; doc/parameters/all.prm lists every key).
 * @ingroup base
 */
#pragma once

#include <string>

namespace shard::sections
{
  inline const std::string simulation           = "A - Simulation";
  inline const std::string mesh                 = "B - Mesh";
  inline const std::string materials            = "C - Materials";
  inline const std::string finite_elements      = "D - Finite elements";
  inline const std::string particles            = "E - Particles";
  inline const std::string particle_formulation = "F - Particle formulation";
  inline const std::string conversion           = "G - Conversion";
  inline const std::string contact              = "H - Contact";
  inline const std::string boundary_conditions  = "I - Boundary conditions";
  inline const std::string time_integration     = "J - Time integration";
  inline const std::string output               = "K - Output";
  inline const std::string quantities           = "L - Quantities";
  inline const std::string material_test        = "M - Material test";
  inline const std::string checkpoint           = "N - Checkpoint";
} // namespace shard::sections
