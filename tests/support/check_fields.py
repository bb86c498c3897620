#!/usr/bin/env python3
# SPDX-License-Identifier: LGPL-2.1-or-later
"""Reads the field files of a run the way ParaView does and checks them against a rigid translation.

Usage: check_fields.py OUTDIR --velocity VX,VY,VZ [--format hdf5|vtu]

hdf5: solution.xdmf and particles.xdmf are parsed as XML; every grid's geometry, topology and
attributes are read from the .h5 files they name (h5py). vtu: the particle series (ASCII
.vtu pieces listed by particles.pvd and the .pvtu files) is read; the mesh .vtu files are
deal.II's compressed binary and are only checked to exist.
Closed form of a body translating at v0: velocity = v0 everywhere, displacement = v0 t, and
position - displacement the same at every output. Counts: the mesh has summary.json's n_elements cells
(8 points each: deal.II writes each cell as its own patch), the particle series summary.json's
n_particles points. Every output time appears once, in increasing order.
Exits 1 with the failed checks listed.
"""
import argparse
import json
import os
import sys
import xml.etree.ElementTree as ET

import numpy as np

failures = []


def check(ok, what):
    print(("ok    " if ok else "FAIL  ") + what)
    if not ok:
        failures.append(what)


def read_hdf5_item(outdir, item):
    import h5py
    file, path = item.text.strip().split(":")
    with h5py.File(os.path.join(outdir, file), "r") as f:
        data = np.array(f[path])
    dims = [int(x) for x in item.get("Dimensions").split()]
    return data.reshape(dims)


def read_xdmf(outdir, name):
    """[(time, points, n_cells, {attribute: array})] of every grid of OUTDIR/NAME; each attribute's
    rows are checked against its centre (Node: one per point, Cell: one per cell)."""
    grids = []
    root = ET.parse(os.path.join(outdir, name)).getroot()
    for grid in root.iter("Grid"):
        if grid.get("GridType") != "Uniform":
            continue
        time = float(grid.find("Time").get("Value"))
        points = read_hdf5_item(outdir, grid.find("Geometry/DataItem"))
        topology = grid.find("Topology")
        n_cells = int(topology.get("NumberOfElements"))
        cells = read_hdf5_item(outdir, topology.find("DataItem"))
        check(cells.shape[0] == n_cells and cells.max() < len(points) and cells.min() >= 0,
              f"{name} t={time:g}: {n_cells} cells ({topology.get('TopologyType')}) index {len(points)} points")
        attributes = {}
        for a in grid.findall("Attribute"):
            values = read_hdf5_item(outdir, a.find("DataItem"))
            rows = len(points) if a.get("Center") == "Node" else n_cells
            check(values.shape[0] == rows, f"{name} t={time:g}: {a.get('Name')} has {values.shape[0]} rows "
                                           f"({a.get('Center')}: {rows})")
            attributes[a.get("Name")] = values
        grids.append((time, points, n_cells, attributes))
    return grids


def read_vtu_particles(outdir):
    grids = []
    root = ET.parse(os.path.join(outdir, "particles.pvd")).getroot()
    for ds in root.iter("DataSet"):
        time = float(ds.get("timestep"))
        pvtu = ET.parse(os.path.join(outdir, ds.get("file"))).getroot()
        points, attributes = [], {}
        for piece in pvtu.iter("Piece"):
            vtu = ET.parse(os.path.join(outdir, piece.get("Source"))).getroot()
            text = vtu.find(".//Points/DataArray").text.split()
            points.append(np.array(text, dtype=float).reshape(-1, 3))
            for a in vtu.find(".//PointData"):
                n = int(a.get("NumberOfComponents", "1"))
                attributes.setdefault(a.get("Name"), []).append(np.array(a.text.split(), dtype=float).reshape(-1, n))
        points = np.concatenate(points)
        grids.append((time, points, len(points), {k: np.concatenate(v) for k, v in attributes.items()}))
    return grids


def check_series(name, grids, v0, n_points, tol, position_digits):
    """n_points: the expected number of points, or None (not checked)."""
    times = [g[0] for g in grids]
    check(len(grids) >= 2 and all(b > a for a, b in zip(times, times[1:])),
          f"{name}: {len(grids)} outputs at increasing times {times}")
    reference = None
    for time, points, n_cells, attributes in grids:
        if n_points is not None:
            check(len(points) == n_points, f"{name} t={time:g}: {len(points)} points, expected {n_points}")
        u = attributes["displacement"].reshape(-1, 3)
        v = attributes["velocity"].reshape(-1, 3)
        scale = max(np.linalg.norm(v0), 1e-300)
        check(np.abs(v - v0).max() <= tol * scale,
              f"{name} t={time:g}: velocity = v0 to {np.abs(v - v0).max() / scale:.2e} (<= {tol:g})")
        du = np.abs(u - v0 * time).max()
        check(du <= tol * scale * max(time, 1e-300) + 1e-300,
              f"{name} t={time:g}: displacement = v0 t to {du / (scale * max(time, 1e-300)):.2e} relative")
        x0 = points - u
        if reference is None:
            reference = x0
        else:
            drift = np.abs(x0 - reference).max()
            bound = tol * np.abs(u).max() + 2 * 10.0 ** -position_digits * np.abs(points).max()
            check(drift <= bound, f"{name} t={time:g}: position - displacement constant to {drift:.1e} m "
                                  f"(<= {bound:.1e})")
        for key in ("stress_xx", "von_mises_stress", "mpi_rank", "material"):
            check(key in attributes, f"{name} t={time:g}: field {key} present")


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("outdir")
    ap.add_argument("--velocity", required=True)
    ap.add_argument("--format", default="hdf5", choices=("hdf5", "vtu"))
    ap.add_argument("--mesh-vertices", type=int, help="distinct vertices of the mesh (hdf5)")
    # deal.II keeps patch data in single precision (DataOutBase::Patch::data is a float
    # table), so the HDF5 fields and the mesh .vtu carry about 7 digits; positions are double.
    ap.add_argument("--tol", type=float, default=2e-7)
    args = ap.parse_args()
    v0 = np.array([float(x) for x in args.velocity.split(",")])
    with open(os.path.join(args.outdir, "summary.json")) as f:
        summary = json.load(f)
    n_particles = int(summary["n_particles"])
    n_cells = int(summary["n_elements"])  # cells of the mesh, converted ones included
    if args.format == "hdf5":
        for stale in ("solution.pvd", "particles.pvd"):
            check(not os.path.exists(os.path.join(args.outdir, stale)), f"no {stale} beside the XDMF series")
        check(summary["files"]["fields"].endswith("solution.xdmf"), "summary.json files/fields names solution.xdmf")
        mesh = read_xdmf(args.outdir, "solution.xdmf")
        for time, points, cells, attributes in mesh:
            check(cells == n_cells, f"solution.xdmf t={time:g}: {cells} cells, summary n_elements {n_cells}")
            converted = int(round(float(np.sum(attributes["converted"]))))
            check(converted == int(summary["n_converted_elements"]),
                  f"solution.xdmf t={time:g}: {converted} cells converted, summary {summary['n_converted_elements']}")
            if args.mesh_vertices is not None:
                x0 = points - attributes["displacement"].reshape(-1, 3)
                distinct = len(np.unique(np.round(x0 / 1e-9).astype(np.int64), axis=0))
                check(distinct == args.mesh_vertices,
                      f"solution.xdmf t={time:g}: {distinct} distinct vertices of {len(points)} points "
                      f"(expected {args.mesh_vertices})")
        check_series("solution.xdmf", mesh, v0, None, args.tol, 15)
        particles = read_xdmf(args.outdir, "particles.xdmf")
        check([g[0] for g in particles] == [g[0] for g in mesh], "particles.xdmf has the output times of the mesh")
    else:
        check(os.path.exists(os.path.join(args.outdir, "solution.pvd")), "solution.pvd written")
        particles = read_vtu_particles(args.outdir)
    # Positions: doubles in HDF5, 9 significant digits in the ASCII particle .vtu.
    check_series("particles", particles, v0, n_particles, args.tol, 15 if args.format == "hdf5" else 9)
    if failures:
        print(f"{len(failures)} field check(s) failed")
        sys.exit(1)
    print("field files: all checks passed")


if __name__ == "__main__":
    main()
