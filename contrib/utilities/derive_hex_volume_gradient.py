#!/usr/bin/env python3
# SPDX-License-Identifier: LGPL-2.1-or-later
"""Derive the exact volume of a trilinear hexahedron and its gradient with respect to
the nodal coordinates (the Flanagan-Belytschko uniform-strain B vectors).

Node order is deal.II's lexicographic order: node a has reference corner
(a & 1, (a >> 1) & 1, (a >> 2) & 1). The volume is a cubic polynomial of the
coordinates; dV/dx_a is quadratic. The script prints the gradient of V with
respect to the x coordinates as a sum of products y_b z_c; the y and z gradients
follow by cyclic permutation (x, y, z) -> (y, z, x) -> (z, x, y).

Used once to write source/fe/hex_kernel.cc; a unit test checks the result
against finite differences of the volume.
"""
import sympy as sp

xi, eta, zeta = sp.symbols("xi eta zeta")
X = sp.symbols("x0:8")
Y = sp.symbols("y0:8")
Z = sp.symbols("z0:8")
N = []
for a in range(8):
    s = [(a >> k) & 1 for k in range(3)]
    f = 1
    for sk, v in zip(s, (xi, eta, zeta)):
        f *= (v if sk else (1 - v))
    N.append(f)
pos = [sum(N[a] * C[a] for a in range(8)) for C in (X, Y, Z)]
J = sp.Matrix(3, 3, lambda i, j: sp.diff(pos[i], (xi, eta, zeta)[j]))
V = sp.integrate(sp.expand(J.det()), (xi, 0, 1), (eta, 0, 1), (zeta, 0, 1))
V = sp.expand(V)
for a in range(8):
    g = sp.factor_terms(sp.expand(sp.diff(V, X[a]) * 12))
    print(f"dV/dx{a} * 12 =", g)

# Emit the C++ table. The 18 terms of 12 dV/dx_a pair up antisymmetrically,
# sign * (y_b z_c - y_c z_b), so that the whole vector is
#   12 grad_{x_a} V = sum over 9 pairs of sign * (x_b cross x_c),  b < c.
print("constexpr std::int8_t hex_volume_gradient_pairs[8][9][3] = {")
for a in range(8):
    g = sp.Poly(sp.expand(sp.diff(V, X[a]) * 12), *(Y + Z))
    coeff = {}
    for monom, c in g.terms():
        b = [i for i in range(8) if monom[i] == 1][0]
        d = [i for i in range(8) if monom[8 + i] == 1][0]
        coeff[(b, d)] = int(c)
    pairs = []
    for (b, d), c in sorted(coeff.items()):
        if b < d:
            assert coeff.get((d, b)) == -c, "terms must pair antisymmetrically"
            pairs.append((b, d, c))
    assert len(pairs) == 9
    print("  {" + ", ".join(f"{{{b}, {d}, {s}}}" for b, d, s in pairs) + "},")
print("};")
