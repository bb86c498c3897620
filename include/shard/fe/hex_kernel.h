// SPDX-License-Identifier: LGPL-2.1-or-later
/**
 * @file hex_kernel.h
 * @brief Geometry kernels of the uniform-strain trilinear hexahedron.
 * @ingroup fe
 *
 * Node order is deal.II's lexicographic order: node a sits at the reference corner
 * ((a & 1), (a >> 1) & 1, (a >> 2) & 1).
 */
#pragma once

#include <array>
#include <cmath>

namespace shard::fe
{
  /**
   * @brief Exact volume of a trilinear hexahedron and its gradient with respect to the nodes.
   *
   * @f$ B_a = \partial V / \partial x_a = \int_{\Omega_e} \nabla N_a \, dV @f$ (Flanagan and
   * Belytschko 1981), so that the mean velocity gradient is
   * @f$ \bar L = V^{-1} \sum_a v_a \otimes B_a @f$ and the mean volumetric rate is exact
   * (mean dilatation). The formula comes from contrib/utilities/derive_hex_volume_gradient.py:
   * @f$ 12 B_a = \sum_{(b,c)} s_{abc}\, x_b \times x_c @f$ over nine node pairs.
   *
   * @param[in] x  nodal coordinates x[a][i]
   * @param[out] B volume gradient B[a][i]
   * @return the volume (negative for an inverted element)
   */
  double
  hex_volume_gradient(const double (&x)[8][3], double (&B)[8][3]);

  /**
   * @brief Largest face area of the hexahedron (each face as half the cross product of its
   * diagonals), for the characteristic length V / A_max.
   */
  double
  hex_max_face_area(const double (&x)[8][3]);

  /**
   * @brief Flanagan-Belytschko hourglass shape vectors
   * @f$ \gamma_{\alpha a} = \Gamma_{\alpha a} - V^{-1} (\Gamma_\alpha \cdot x_i) B_{ai} @f$,
   * orthogonal to every linear velocity field.
   */
  void
  hex_hourglass_vectors(const double (&x)[8][3], const double (&B)[8][3], double volume,
                        double (&gamma)[4][8]);
} // namespace shard::fe
