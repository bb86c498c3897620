#!/usr/bin/env python3
# SPDX-License-Identifier: LGPL-2.1-or-later
"""Plot impact-face radius and bar length against time for each run of contrib/taylor_study:
elements (directories h<size>, solid lines), particles (particles_h<size>, dashed lines) and
hybrid, impact end converted to particles (hybrid_h<size>, dash-dotted lines); the same colour
per size."""
import csv
import glob
import os
import sys

import matplotlib
matplotlib.use("Agg")
import matplotlib.pyplot as plt

study, png = sys.argv[1], sys.argv[2]
fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(10, 4))
# directory prefix -> (label, line style, order)
METHODS = {"": ("FE", "-", 0), "particles_": ("particles", "--", 1), "hybrid_": ("hybrid", "-.", 2)}
runs = []
for d in glob.glob(os.path.join(study, "*h*")):
    base = os.path.basename(d)
    method, _, size = base.rpartition("h")
    if method not in METHODS or not os.path.exists(os.path.join(d, "history.csv")):
        continue
    try:
        runs.append((float(size), method, d))
    except ValueError:
        continue
sizes = sorted({s for s, _, _ in runs}, reverse=True)
colors = {s: f"C{i}" for i, s in enumerate(sizes)}
for size, method, d in sorted(runs, key=lambda r: (METHODS[r[1]][2], -r[0])):
    rows = list(csv.DictReader(open(os.path.join(d, "history.csv"))))
    t = [1e6 * float(r["time"]) for r in rows]
    name, ls, _ = METHODS[method]
    style = dict(color=colors[size], ls=ls, label=f"{name}, h = {size:g} mm")
    ax1.plot(t, [1e3 * float(r["impact_radius"]) for r in rows], **style)
    ax2.plot(t, [1e3 * float(r["length"]) for r in rows], **style)
for ax, name, ref in ((ax1, "impact-face radius (mm)", [(7.12, "Simo 1992", "top"),
                                                        (7.22, "Foulk et al. 2021, converged Q1/P0", "bottom")]),
                      (ax2, "bar length (mm)", [])):
    for value, source, where in ref:
        ax.axhline(value, ls=":", color="gray")
        ax.annotate(source, (2, value), fontsize=7, color="gray", va=where)
    ax.set_xlabel("time (us)")
    ax.set_ylabel(name)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7)
fig.suptitle("Copper Taylor bar, 227 m/s, bilinear J2 (prm/benchmarks/taylor_bar.prm):\n"
             "FE solid, particles dashed, hybrid (z <= 8 mm as particles) dash-dotted", fontsize=10)
fig.tight_layout()
fig.savefig(png, dpi=120)
print("wrote", png)
