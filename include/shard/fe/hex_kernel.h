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

  /**
   * @brief Hughes-Winget incremental rotation
   * @f$ Q = (I - \tfrac12 \Delta t W)^{-1} (I + \tfrac12 \Delta t W) @f$ from the spin
   * @p W (3x3, skew) and @p dt, as a Cayley transform of the axial vector.
   */
  void
  hughes_winget_rotation(const double (&W)[3][3], double dt, double (&Q)[3][3]);

  /// Rotates a symmetric tensor in 6-component storage: s <- Q s Q^T.
  void
  rotate_symmetric(const double (&Q)[3][3], double *s);

  /**
   * @brief Eigenvalues of a symmetric tensor in 6-component storage (xx, yy, zz, yz, xz, xy),
   * ascending, by the trigonometric solution of the characteristic equation (exact for a
   * diagonal tensor; all equal to the mean when the deviator is below 1e-15 of it).
   */
  std::array<double, 3>
  symmetric_eigenvalues(const double *s);

  /// Principal stretches of F (row-major): square roots of the eigenvalues of F^T F, ascending.
  std::array<double, 3>
  principal_stretches(const double *F);

  /**
   * @brief Bulk viscosity pressure q = rho L (Q2 L r^2 - Q1 c r), r = tr(de) / dt, in compression
   * (tr(de) < 0) and 0 otherwise (LS-DYNA's form; elements and particles).
   * @param rho current density (kg/m^3), @param length L (m), @param c wave speed (m/s)
   * @param trace_de tr of the strain increment of the step, @param dt step (s)
   */
  inline double
  bulk_viscosity(const double rho, const double length, const double c, const double trace_de, const double dt,
                 const double q1, const double q2)
  {
    if (!(trace_de < 0 && dt > 0))
      return 0.;
    const double rate = trace_de / dt;
    return rho * length * (q2 * length * rate * rate - q1 * c * rate);
  }

  /**
   * @brief Stable step L / (c (sqrt(1 + r^2) + r)) with the bulk viscosity, r = Q1 - Q2 L tr(de) / (dt c)
   * in compression and Q1 otherwise (LS-DYNA's correction of L / c).
   */
  inline double
  bulk_viscosity_step(const double length, const double c, const double trace_de, const double dt, const double q1,
                      const double q2)
  {
    const double r = q1 - (trace_de < 0 && dt > 0 ? q2 * length * trace_de / dt / c : 0.);
    return length / (c * (std::sqrt(1 + r * r) + r));
  }
} // namespace shard::fe
