#!/usr/bin/env python3
# SPDX-License-Identifier: LGPL-2.1-or-later
"""Writes bar.msh: a Gmsh 2.2 ASCII mesh of a 0.1 x 0.004 x 0.004 m bar, 50 x 2 x 2 hexahedra,
in millimetres (the scene sets mesh scale = 0.001). Physical surfaces: 1 on x = 0, 2 on x = 100,
3 on the four lateral faces; physical volume 1."""
nx, ny, nz, lx, ly, lz = 50, 2, 2, 100.0, 4.0, 4.0
def node(i, j, k):
    return 1 + i + (nx + 1) * (j + (ny + 1) * k)
nodes = [(node(i, j, k), i * lx / nx, j * ly / ny - ly / 2, k * lz / nz - lz / 2)
         for k in range(nz + 1) for j in range(ny + 1) for i in range(nx + 1)]
elements = []
def quad(tag, a, b, c, d):
    elements.append((3, tag, (a, b, c, d)))
for j in range(ny):
    for k in range(nz):
        quad(1, node(0, j, k), node(0, j, k + 1), node(0, j + 1, k + 1), node(0, j + 1, k))
        quad(2, node(nx, j, k), node(nx, j + 1, k), node(nx, j + 1, k + 1), node(nx, j, k + 1))
for i in range(nx):
    for k in range(nz):
        quad(3, node(i, 0, k), node(i + 1, 0, k), node(i + 1, 0, k + 1), node(i, 0, k + 1))
        quad(3, node(i, ny, k), node(i, ny, k + 1), node(i + 1, ny, k + 1), node(i + 1, ny, k))
    for j in range(ny):
        quad(3, node(i, j, 0), node(i, j + 1, 0), node(i + 1, j + 1, 0), node(i + 1, j, 0))
        quad(3, node(i, j, nz), node(i + 1, j, nz), node(i + 1, j + 1, nz), node(i, j + 1, nz))
for k in range(nz):
    for j in range(ny):
        for i in range(nx):
            elements.append((5, 1, (node(i, j, k), node(i + 1, j, k), node(i + 1, j + 1, k), node(i, j + 1, k),
                                    node(i, j, k + 1), node(i + 1, j, k + 1), node(i + 1, j + 1, k + 1),
                                    node(i, j + 1, k + 1))))
with open("bar.msh", "w") as f:
    f.write("$MeshFormat\n2.2 0 8\n$EndMeshFormat\n$Nodes\n%d\n" % len(nodes))
    for n, x, y, z in nodes:
        f.write(f"{n} {x:.6g} {y:.6g} {z:.6g}\n")
    f.write("$EndNodes\n$Elements\n%d\n" % len(elements))
    for e, (etype, tag, vs) in enumerate(elements, 1):
        f.write(f"{e} {etype} 2 {tag} {tag} " + " ".join(map(str, vs)) + "\n")
    f.write("$EndElements\n")
