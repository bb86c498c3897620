#!/usr/bin/env python3
# SPDX-License-Identifier: LGPL-2.1-or-later
"""Critical explicit step of one-point hexahedra with lumped mass, as a fraction of L/c.

Assembles the one-point (mean-gradient) stiffness of a block of nx x ny x nz unit cubes, without
hourglass control, with the lumped mass rho V / 8 per element node, and prints
dt_crit / (h / c_L) = 2 / (omega_max h / c_L) for several Poisson's ratios. A fraction below the
safety factor means the default step L/c (L = V / A_max = h) is unstable for that block.
Used for doc/validation.md ("Stability on stiff and extreme cases").

Usage: contrib/utilities/hex_critical_step.py      (needs numpy)
"""
import numpy as np


def critical_fraction(nu, nx, ny, nz):
    lam, mu = nu / ((1 + nu) * (1 - 2 * nu)), 1 / (2 * (1 + nu))  # E = 1, rho = 1, h = 1
    node = lambda i, j, k: (i * (ny + 1) + j) * (nz + 1) + k
    n = (nx + 1) * (ny + 1) * (nz + 1)
    K, M = np.zeros((3 * n, 3 * n)), np.zeros(3 * n)
    corners = [(a, b, c) for a in (0, 1) for b in (0, 1) for c in (0, 1)]
    D = np.zeros((6, 6))
    D[:3, :3] = lam
    D[range(3), range(3)] += 2 * mu
    D[3:, 3:] = mu * np.eye(3)
    B = np.zeros((6, 24))
    for I, (a, b, c) in enumerate(corners):
        g = [(2 * a - 1) / 4, (2 * b - 1) / 4, (2 * c - 1) / 4]  # mean gradient of N_I
        B[0, 3 * I], B[1, 3 * I + 1], B[2, 3 * I + 2] = g
        B[3, 3 * I], B[3, 3 * I + 1] = g[1], g[0]
        B[4, 3 * I + 1], B[4, 3 * I + 2] = g[2], g[1]
        B[5, 3 * I], B[5, 3 * I + 2] = g[2], g[0]
    Ke = B.T @ D @ B
    for i in range(nx):
        for j in range(ny):
            for k in range(nz):
                dofs = [3 * node(i + a, j + b, k + c) + d for a, b, c in corners for d in range(3)]
                K[np.ix_(dofs, dofs)] += Ke
                M[dofs] += 1 / 8
    omega = np.sqrt(np.linalg.eigvalsh(K / np.sqrt(np.outer(M, M))).max())
    return 2 / omega * np.sqrt(lam + 2 * mu)


print("| nu | 1 element | 2 x 2 x 4 | 4 x 4 x 6 |")
print("|---|---|---|---|")
for nu in (0.0, 0.3, 0.45, 0.49, 0.4999):
    print(f"| {nu} | " + " | ".join(f"{critical_fraction(nu, *s):.3f}" for s in ((1, 1, 1), (2, 2, 4), (4, 4, 6))) + " |")
