#!/usr/bin/python3
# SPDX-License-Identifier: LGPL-2.1-or-later
"""Load against platen displacement of the K&C concrete cylinder
(prm/verification/concrete_cylinder), FE and particles, with the closed-form peak f'c A.

plot_cylinder.py [--fe RUN_DIR] [--particles RUN_DIR] DOC_DIR

With --fe / --particles (output directories of `shard run concrete_cylinder.prm`, the particle
run with --set "E - Particles/bodies=cylinder"), their history.csv is converted into
DOC_DIR/concrete_cylinder_fe.csv and DOC_DIR/concrete_cylinder_particles.csv
(time_s, displacement_m, axial_strain, load_N, support_N, max_radius_m; load and support
positive in compression). The plot DOC_DIR/concrete_cylinder.png is always drawn from these CSVs,
so it can be redrawn without running shard:

  build/bin/shard run prm/verification/concrete_cylinder/concrete_cylinder.prm \\
      --set "K - Output/directory=/tmp/cyl_fe" --set "K - Output/history interval=5"
  build/bin/shard run prm/verification/concrete_cylinder/concrete_cylinder.prm \\
      --set "K - Output/directory=/tmp/cyl_particles" --set "K - Output/history interval=5" \\
      --set "E - Particles/bodies=cylinder"
  contrib/utilities/plot_cylinder.py --fe /tmp/cyl_fe --particles /tmp/cyl_particles doc/materials
"""
import argparse
import csv
import math
import os

import matplotlib
matplotlib.use("Agg")
import matplotlib.pyplot as plt

FC = 48e6        # compressive strength f'c (Pa)
RADIUS = 0.025   # cylinder radius (m)
HEIGHT = 0.1     # cylinder height (m)
FCA = FC * math.pi * RADIUS ** 2   # 94 247.8 N
COLUMNS = ["time_s", "displacement_m", "axial_strain", "load_N", "support_N", "max_radius_m"]


def convert(run_dir, csv_path):
    """history.csv of a run -> the CSV of load against platen displacement."""
    with open(os.path.join(run_dir, "history.csv")) as f:
        rows = list(csv.DictReader(f))
    top0 = float(rows[0]["top_z"])
    with open(csv_path, "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(COLUMNS)
        for r in rows:
            u = top0 - float(r["top_z"])
            w.writerow([f"{float(r['time']):.6e}", f"{u:.6e}", f"{u / HEIGHT:.6e}",
                        f"{-float(r['load']):.6e}", f"{float(r['support']):.6e}",
                        f"{float(r['radius']):.6e}"])
    print("wrote", csv_path)


def read(csv_path):
    with open(csv_path) as f:
        rows = list(csv.DictReader(f))
    return [float(r["displacement_m"]) for r in rows], [float(r["load_N"]) for r in rows]


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--fe", help="output directory of the FE run")
    ap.add_argument("--particles", help="output directory of the particle run")
    ap.add_argument("doc_dir", help="directory of the CSVs and the PNG (doc/materials)")
    args = ap.parse_args()
    curves = [("fe", "FE (hexahedra, h = 5 mm)", "C0", "-"),
              ("particles", "particles (SPG, spacing 5 mm)", "C1", "--")]
    for key, run in (("fe", args.fe), ("particles", args.particles)):
        if run:
            convert(run, os.path.join(args.doc_dir, f"concrete_cylinder_{key}.csv"))
    fig, ax = plt.subplots(figsize=(6.4, 4.4))
    for key, label, color, ls in curves:
        path = os.path.join(args.doc_dir, f"concrete_cylinder_{key}.csv")
        if not os.path.exists(path):
            continue
        u, load = read(path)
        k = max(range(len(load)), key=lambda i: load[i])
        ax.plot([1e3 * x for x in u], [1e-3 * y for y in load], color=color, ls=ls,
                label=f"{label}: peak {1e-3 * load[k]:.1f} kN = {load[k] / FCA:.3f} f'c A")
    ax.axhline(1e-3 * FCA, color="gray", ls=":")
    ax.axhspan(0.9e-3 * FCA, 1.1e-3 * FCA, color="gray", alpha=0.12, lw=0)
    ax.annotate(f"f'c A = {1e-3 * FCA:.1f} kN (band: 10 %)", (0.01, 1e-3 * FCA), xycoords=("axes fraction", "data"),
                fontsize=8, color="gray", va="bottom")
    ax.set_xlabel("platen displacement (mm)")
    ax.set_ylabel("platen load (kN)")
    ax.set_ylim(bottom=-5, top=1.25e-3 * FCA)
    ax.set_xlim(left=0)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8, loc="center right")
    ax.set_title("K&C concrete cylinder 50 x 100 mm, f'c = 48 MPa,\nfrictionless platens, 0.2 m/s, rate effects off",
                 fontsize=9)
    fig.tight_layout()
    png = os.path.join(args.doc_dir, "concrete_cylinder.png")
    fig.savefig(png, dpi=120)
    print("wrote", png)


if __name__ == "__main__":
    main()
