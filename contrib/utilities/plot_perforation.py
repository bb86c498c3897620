#!/usr/bin/env python3
"""Pictures of a perforation run (prm/examples/plate_perforation.prm): projectile velocity against
time (history.csv, column v_projectile) and the fragments at the last output (fragments.csv:
centres in the x-z plane, marker area by mass, FE plate and projectile included).
Usage: plot_perforation.py OUTPUT_DIR PNG"""
import csv
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402


def main():
    out, png = sys.argv[1], sys.argv[2]
    with open(f"{out}/history.csv") as f:
        rows = list(csv.DictReader(f))
    t = [1e6 * float(r["time"]) for r in rows]
    v = [-float(r["v_projectile"]) for r in rows]
    with open(f"{out}/fragments.csv") as f:
        frags = list(csv.DictReader(f))
    last = max(float(r["time"]) for r in frags)
    final = [r for r in frags if float(r["time"]) == last]
    fig, (a, b) = plt.subplots(1, 2, figsize=(11, 4.2))
    a.plot(t, v, "k-")
    a.set_xlabel("time (us)")
    a.set_ylabel("projectile speed (m/s)")
    a.set_title(f"residual speed {v[-1]:.0f} m/s")
    a.grid(True, alpha=0.3)
    masses = [float(r["mass"]) for r in final]
    big = max(masses)
    for r, m in zip(final, masses):
        colour = "tab:blue" if int(r["particles"]) == 0 else ("tab:red" if int(r["nodes"]) == 1 else "tab:orange")
        b.scatter(1e3 * float(r["x"]), 1e3 * float(r["z"]), s=4 + 400 * m / big, c=colour, alpha=0.6,
                  edgecolors="none")
    b.set_xlabel("x (mm)")
    b.set_ylabel("z (mm)")
    b.set_aspect("equal")
    b.set_title(f"{len(final)} fragments at {1e6 * last:.0f} us (centres; red: free particles)")
    b.grid(True, alpha=0.3)
    fig.tight_layout()
    fig.savefig(png, dpi=110)


if __name__ == "__main__":
    main()
