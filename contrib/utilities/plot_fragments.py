#!/usr/bin/env python3
# SPDX-License-Identifier: LGPL-2.1-or-later
"""Plot the fragment statistics of a run: plot_fragments.py OUTPUT_DIR [PNG].

Reads OUTPUT_DIR/fragment_statistics.csv (written by `shard run` when the scene has particles)
and writes PNG (default OUTPUT_DIR/fragments.png) with two panels:
  left:  cumulative mass fraction of the fragments against fragment mass (largest first, so
         the curve reads "fraction of the mass in fragments at least this heavy");
  right: mass-weighted distribution of the fragment speeds.
"""
import csv
import os
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402


def main():
    if len(sys.argv) < 2:
        raise SystemExit(__doc__)
    out_dir = sys.argv[1]
    png = sys.argv[2] if len(sys.argv) > 2 else os.path.join(out_dir, "fragments.png")
    with open(os.path.join(out_dir, "fragment_statistics.csv")) as f:
        rows = list(csv.DictReader(f))
    if not rows:
        raise SystemExit("no fragments in fragment_statistics.csv")
    mass = [float(r["mass"]) for r in rows]
    cumulative = [float(r["cumulative_mass_fraction"]) for r in rows]
    speed = [float(r["speed"]) for r in rows]
    time = float(rows[0]["time"])
    total = sum(mass)

    fig, (a, b) = plt.subplots(1, 2, figsize=(10, 4))
    a.step([m * 1e3 for m in mass], cumulative, where="post", marker="o", ms=3)
    a.set_xscale("log")
    a.set_xlabel("fragment mass (g)")
    a.set_ylabel("cumulative mass fraction (largest first)")
    a.set_ylim(0, 1.05)
    a.grid(True, which="both", alpha=0.3)
    a.set_title(f"{len(rows)} fragments, total {total * 1e3:.4g} g")

    bins = min(30, max(5, len(rows)))
    b.hist(speed, bins=bins, weights=[m / total for m in mass])
    b.set_xlabel("fragment speed (m/s)")
    b.set_ylabel("mass fraction")
    b.grid(True, alpha=0.3)
    b.set_title(f"speeds at t = {time:.4g} s")
    fig.tight_layout()
    fig.savefig(png, dpi=120)
    print(png)


if __name__ == "__main__":
    main()
