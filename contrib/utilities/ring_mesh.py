#!/usr/bin/env python3
# SPDX-License-Identifier: LGPL-2.1-or-later
"""Writes a Gmsh 2.2 ASCII mesh of a thin ring of hexahedra for the fragmentation check
(prm/verification/fragmentation/ring.prm, contrib/fragmentation,
doc/manual/fragmentation_ring_draft.md).

The ring lies in the x-y plane, centred at the origin: mean radius R, square cross-section
t x t (radially from R - t/2 to R + t/2, axially from -t/2 to t/2). The cross-section has
n_t = t / h cells per side (t / h must be a whole number), the circumference
n_theta = round(2 pi R / h) cells (the arc length of a cell at R is 2 pi R / n_theta, printed).
Coordinates are written in metres (the scene uses mesh scale = 1).

Jitter (--jitter a, --seed s): every node is moved by a uniform random amount in
[-a h, a h] along each direction in which it is interior: along the circumference (the
angle, at its own radius) for every node, radially for nodes off the inner and outer
faces, axially for nodes off the bottom and top faces. The nodes of the four faces only
slide within them (the inner and outer ones along their circles), so the ring keeps its
shape and its mass (to second order in a, through the facets) while the cell sizes, and with
them the particle volumes, masses, spacings and stencils, vary by up to +-2a h from cell to
cell. The draw is seeded: the
same arguments give the same file byte for byte.

Boundary ids (physical surface tags): 1 inner face, 2 outer face, 3 bottom (z = -t/2),
4 top (z = +t/2); physical volume 1.
"""
import argparse
import math
import random
import sys


def build(R, t, h, jitter, seed):
    n_t = round(t / h)
    if n_t < 1 or abs(n_t * h - t) > 1e-9 * t:
        raise ValueError(f"t / h = {t / h:.6g} is not a whole number (t = {t}, h = {h})")
    n_th = round(2 * math.pi * R / h)
    if n_th < 8:
        raise ValueError(f"2 pi R / h = {2 * math.pi * R / h:.3g}: fewer than 8 cells around")
    if t >= 2 * R:
        raise ValueError("t must be smaller than 2 R")
    if not 0 <= jitter < 0.25:
        raise ValueError("jitter must lie in [0, 0.25) (a fraction of h)")
    rng = random.Random(seed)
    dth = 2 * math.pi / n_th

    def node(i, j, k):  # i radial, j circumferential (periodic), k axial
        return 1 + i + (n_t + 1) * ((j % n_th) + n_th * k)

    nodes = []
    for k in range(n_t + 1):
        for j in range(n_th):
            for i in range(n_t + 1):
                r = R - t / 2 + i * h
                th = j * dth
                z = -t / 2 + k * h
                if jitter > 0:
                    # Always draw three numbers, so that the sequence does not depend on which
                    # directions are interior.
                    u = [rng.uniform(-1, 1) for _ in range(3)]
                    th += u[1] * jitter * h / r
                    if 0 < i < n_t:
                        r += u[0] * jitter * h
                    if 0 < k < n_t:
                        z += u[2] * jitter * h
                nodes.append((node(i, j, k), r * math.cos(th), r * math.sin(th), z))
    elements = []
    for j in range(n_th):
        for k in range(n_t):  # inner (i = 0, normal -r) and outer (i = n_t, normal +r) faces
            elements.append((3, 1, (node(0, j, k), node(0, j, k + 1), node(0, j + 1, k + 1), node(0, j + 1, k))))
            elements.append((3, 2, (node(n_t, j, k), node(n_t, j + 1, k), node(n_t, j + 1, k + 1), node(n_t, j, k + 1))))
        for i in range(n_t):  # bottom (k = 0, normal -z) and top (k = n_t, normal +z) faces
            elements.append((3, 3, (node(i, j, 0), node(i, j + 1, 0), node(i + 1, j + 1, 0), node(i + 1, j, 0))))
            elements.append((3, 4, (node(i, j, n_t), node(i + 1, j, n_t), node(i + 1, j + 1, n_t), node(i, j + 1, n_t))))
    for k in range(n_t):
        for j in range(n_th):
            for i in range(n_t):
                # (r, theta, z) is right-handed: the bottom face counter-clockwise seen from +z.
                elements.append((5, 1, (node(i, j, k), node(i + 1, j, k), node(i + 1, j + 1, k), node(i, j + 1, k),
                                        node(i, j, k + 1), node(i + 1, j, k + 1), node(i + 1, j + 1, k + 1),
                                        node(i, j + 1, k + 1))))
    info = {"n_t": n_t, "n_theta": n_th, "arc_cell": 2 * math.pi * R / n_th, "nodes": len(nodes),
            "hexahedra": n_t * n_t * n_th, "volume": 2 * math.pi * R * t * t}
    return nodes, elements, info


def write(path, nodes, elements):
    with open(path, "w") as f:
        f.write("$MeshFormat\n2.2 0 8\n$EndMeshFormat\n$Nodes\n%d\n" % len(nodes))
        for n, x, y, z in nodes:
            f.write(f"{n} {x:.15g} {y:.15g} {z:.15g}\n")
        f.write("$EndNodes\n$Elements\n%d\n" % len(elements))
        for e, (etype, tag, vs) in enumerate(elements, 1):
            f.write(f"{e} {etype} 2 {tag} {tag} " + " ".join(map(str, vs)) + "\n")
        f.write("$EndElements\n")


def main():
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("output", help="the .msh file to write")
    p.add_argument("--radius", type=float, default=0.2, help="mean radius R (m), default 0.2")
    p.add_argument("--thickness", type=float, default=0.008, help="side t of the square cross-section (m), default 0.008")
    p.add_argument("--size", type=float, default=0.002, help="element size h (m), t / h whole, default 0.002")
    p.add_argument("--jitter", type=float, default=0.03, help="node jitter as a fraction of h, default 0.03; 0 off")
    p.add_argument("--seed", type=int, default=1, help="seed of the jitter, default 1")
    a = p.parse_args()
    try:
        nodes, elements, info = build(a.radius, a.thickness, a.size, a.jitter, a.seed)
    except ValueError as e:
        sys.exit(f"ring_mesh.py: {e}")
    write(a.output, nodes, elements)
    print(f"ring_mesh.py: {a.output}: R = {a.radius} m, t = {a.thickness} m, {info['n_t']} x {info['n_t']} x "
          f"{info['n_theta']} hexahedra (arc {info['arc_cell'] * 1e3:.4f} mm at R), {info['nodes']} nodes, "
          f"jitter {a.jitter} h, seed {a.seed}")


if __name__ == "__main__":
    main()
