#!/usr/bin/env python3
# SPDX-License-Identifier: LGPL-2.1-or-later
"""Picture of the final state of a hybrid impact run (the showcase, prm/examples/showcase.prm):
plot_showcase.py OUTPUT_DIR [PNG] (default OUTPUT_DIR/showcase.png).

Left: a section through the shot line (|y| below half an element size) of the last field output:
the FE cells still intact (grey: target, blue: projectile), the particles in the section (orange:
bonded, red: free particles, i.e. all bonds broken). Right: projectile speed (history column
v_projectile), converted elements and broken bonds against time.

Reads solution_NNNN.R.vtu (deal.II binary, zlib) and particles_NNNN.R.vtu (ASCII) of the last
output of every rank, and history.csv. Needs python3-numpy and python3-matplotlib.
"""
import csv
import os
import sys

import numpy as np
import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
from matplotlib.collections import PolyCollection  # noqa: E402

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from shard_output import last_fragments, last_pieces, read_vtu  # noqa: E402


def arrays(path):
    """read_vtu() as numpy arrays of shape (n, components)."""
    return {k: np.asarray(v, dtype=float).reshape(-1, c) if c > 1 else np.asarray(v, dtype=float)
            for k, (v, c) in read_vtu(path).items()}

def hull(p):
    """Convex hull of 2-D points (monotone chain), counter-clockwise."""
    p = sorted(set(map(tuple, p)))
    if len(p) < 3:
        return p

    def half(points):
        h = []
        for q in points:
            while len(h) >= 2 and (h[-1][0] - h[-2][0]) * (q[1] - h[-2][1]) - (h[-1][1] - h[-2][1]) * (q[0] - h[-2][0]) <= 0:
                h.pop()
            h.append(q)
        return h[:-1]
    return half(p) + half(p[::-1])


def main():
    if len(sys.argv) < 2:
        raise SystemExit(__doc__)
    out = sys.argv[1]
    png = sys.argv[2] if len(sys.argv) > 2 else os.path.join(out, "showcase.png")

    fig, (a, b) = plt.subplots(1, 2, figsize=(12, 5.2), gridspec_kw={"width_ratios": [1.25, 1]})
    spacing = None
    cells_drawn = 0
    for f in last_pieces(out, "solution"):
        d = arrays(f)
        x = d["Points"].reshape(-1, 8, 3)
        material = d["material"].reshape(-1, 8)[:, 0]
        converted = d["converted"].reshape(-1, 8)[:, 0]
        centre = x.mean(axis=1)
        size = np.abs(x[:, :, 1].max(axis=1) - x[:, :, 1].min(axis=1))
        keep = (converted < 0.5) & (np.abs(centre[:, 1]) < 0.5 * size)
        polys = [hull(1e3 * x[c][:, [0, 2]]) for c in np.nonzero(keep)[0]]
        colours = ["#4a78b5" if m < 0.5 else "#b0b0b0" for m in material[keep]]
        a.add_collection(PolyCollection(polys, facecolors=colours, edgecolors="#606060", linewidths=0.2))
        cells_drawn += len(polys)
    for f in last_pieces(out, "particles"):
        d = arrays(f)
        x = d["Points"].reshape(-1, 3)
        volume = d.get("volume", np.ones(len(x)))
        h = np.cbrt(np.median(volume))
        spacing = h if spacing is None else min(spacing, h)
        near = np.abs(x[:, 1]) < 0.5 * h
        a.scatter(1e3 * x[near, 0], 1e3 * x[near, 2], s=6, c="tab:orange", edgecolors="none", label=None)
    # Free particles are the one-particle fragments of fragments.csv (last output).
    free = []
    frag_path = os.path.join(out, "fragments.csv")
    if os.path.exists(frag_path):
        last, rows = last_fragments(frag_path)
        if rows:
            free = [r for r in rows if int(r["nodes"]) == 1]
            half = 0.5 * (spacing if spacing else 1e9)
            fx = np.array([[float(r["x"]), float(r["y"]), float(r["z"])] for r in free]).reshape(-1, 3)
            sel = np.abs(fx[:, 1]) < half
            a.scatter(1e3 * fx[sel, 0], 1e3 * fx[sel, 2], s=7, c="tab:red", edgecolors="none")
    a.autoscale_view()
    a.set_aspect("equal")
    a.set_xlabel("x (mm)")
    a.set_ylabel("z (mm)")
    a.set_title(f"section y = 0: FE (grey target, blue projectile), particles (orange), free particles (red)",
                fontsize=9)
    a.grid(True, alpha=0.3)

    with open(os.path.join(out, "history.csv")) as f:
        hist = list(csv.DictReader(f))
    t = [1e6 * float(r["time"]) for r in hist]
    if hist and "v_projectile" in hist[0]:
        v = [-float(r["v_projectile"]) for r in hist]
        b.plot(t, v, "k-", label="projectile speed (m/s)")
        b.set_title(f"residual speed {v[-1]:.0f} m/s at {t[-1]:.0f} us", fontsize=10)
    b.set_xlabel("time (us)")
    b.set_ylabel("projectile speed (m/s)")
    b.grid(True, alpha=0.3)
    c = b.twinx()
    for name, style, label in (("converted_elements", "tab:green", "converted elements"),
                               ("broken_bonds", "tab:purple", "broken bonds / 10"),
                               ("free_particles", "tab:red", "free particles")):
        if hist and name in hist[0]:
            scale = 0.1 if name == "broken_bonds" else 1.0
            c.plot(t, [scale * float(r[name]) for r in hist], color=style, label=label)
    c.set_ylabel("count")
    lines = b.get_legend_handles_labels()[0] + c.get_legend_handles_labels()[0]
    labels = b.get_legend_handles_labels()[1] + c.get_legend_handles_labels()[1]
    b.legend(lines, labels, loc="center left", fontsize=8)
    fig.tight_layout()
    fig.savefig(png, dpi=110)
    print(png)


if __name__ == "__main__":
    main()
