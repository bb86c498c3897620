#!/usr/bin/env python3
# SPDX-License-Identifier: LGPL-2.1-or-later
"""Plot impact-face radius and bar length against time for each run of contrib/taylor_study:
elements (directories h<size>, solid lines) and particles (particles_h<size>, dashed lines, the
same colour per size)."""
import csv
import glob
import os
import sys

import matplotlib
matplotlib.use("Agg")
import matplotlib.pyplot as plt

study, png = sys.argv[1], sys.argv[2]
fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(10, 4))
runs = []
for d in glob.glob(os.path.join(study, "*h*")):
    base = os.path.basename(d)
    method, _, size = base.rpartition("h")
    if method not in ("", "particles_") or not os.path.exists(os.path.join(d, "history.csv")):
        continue
    try:
        runs.append((float(size), method == "particles_", d))
    except ValueError:
        continue
sizes = sorted({s for s, _, _ in runs}, reverse=True)
colors = {s: f"C{i}" for i, s in enumerate(sizes)}
for size, particles, d in sorted(runs, key=lambda r: (r[1], -r[0])):
    rows = list(csv.DictReader(open(os.path.join(d, "history.csv"))))
    t = [1e6 * float(r["time"]) for r in rows]
    label = f"{'particles' if particles else 'FE'}, h = {size:g} mm"
    style = dict(color=colors[size], ls="--" if particles else "-", label=label)
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
fig.suptitle("Copper Taylor bar, 227 m/s, bilinear J2 (prm/benchmarks/taylor_bar.prm): FE solid, particles dashed")
fig.tight_layout()
fig.savefig(png, dpi=120)
print("wrote", png)
