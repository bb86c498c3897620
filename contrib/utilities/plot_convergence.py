#!/usr/bin/env python3
# SPDX-License-Identifier: LGPL-2.1-or-later
"""Plot and tabulate the standing-wave study of contrib/convergence.

Usage: plot_convergence.py CSV PNG [MARKDOWN]
Left panel: L2 displacement error against element size h, log-log, with the least-squares slope
over the three finest sizes of each method. Right panel: the same error against the wall time of
the time loop (solid; set-up and output excluded) and of the whole run (dashed, crosses). Each
method keeps its colour and marker (STYLES) whichever methods the CSV holds. With MARKDOWN,
the text between <!-- CONVERGENCE BEGIN --> and <!-- CONVERGENCE END --> is replaced by the
tables of the runs and of the fitted rates.
"""
import csv
import math
import os
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from doc_tables import replace_marked  # noqa: E402

import matplotlib
matplotlib.use("Agg")
import matplotlib.pyplot as plt

LABELS = {"fe": "FE (hexahedra, viscous hourglass 0.1)",
          "particles": "particles (default: residual 0.1, bulk viscosity 0.06/1.5)",
          "particles_r0": "particles, residual coefficient 0",
          "particles_q0": "particles, no bulk viscosity",
          "hybrid": "hybrid (particles in the central 1/8)"}
# colour and marker of each method (both panels); methods not listed take the next free colour and "o"
STYLES = {"fe": ("C0", "o"), "particles": ("C1", "o"), "particles_r0": ("C2", "o"), "particles_q0": ("C3", "o"),
          "hybrid": ("C4", "s")}


def slope(xs, ys):
    """Least-squares slope of log y against log x."""
    lx, ly = [math.log(x) for x in xs], [math.log(y) for y in ys]
    mx, my = sum(lx) / len(lx), sum(ly) / len(ly)
    return sum((a - mx) * (b - my) for a, b in zip(lx, ly)) / sum((a - mx) ** 2 for a in lx)


def main():
    csv_path, png = sys.argv[1], sys.argv[2]
    rows = list(csv.DictReader(open(csv_path)))
    methods = list(dict.fromkeys(r["method"] for r in rows))
    runs = {m: sorted((r for r in rows if r["method"] == m), key=lambda r: -float(r["h_m"])) for m in methods}
    fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(12, 5))
    rates = {}
    spare = iter(f"C{k}" for k in range(10) if f"C{k}" not in {c for c, _ in STYLES.values()})
    for m in methods:
        rs = runs[m]
        color, marker = STYLES[m] if m in STYLES else (next(spare, "k"), "o")
        h = [1e3 * float(r["h_m"]) for r in rs]
        e = [float(r["relative_error"]) for r in rs]
        loop = [max(float(r["loop_time_s"]), 1e-4) for r in rs]
        wall = [float(r["wall_time_s"]) for r in rs]
        fine = slice(-3, None)
        p_h = slope(h[fine], e[fine]) if len(rs) >= 3 else float("nan")
        p_t = slope(loop[fine], e[fine]) if len(rs) >= 3 else float("nan")
        rates[m] = (p_h, p_t)
        ax1.loglog(h, e, marker + "-", color=color, label=f"{LABELS.get(m, m)}: slope {p_h:.2f}")
        if len(rs) >= 3:
            # fitted line through the three finest points
            lx = [math.log(x) for x in h[fine]]
            ly = [math.log(y) for y in e[fine]]
            c = sum(ly) / 3 - p_h * sum(lx) / 3
            xs = [h[-3] * 1.3, h[-1] / 1.3]
            ax1.loglog(xs, [math.exp(c) * x ** p_h for x in xs], ":", color=color, lw=1)
        ax2.loglog(loop, e, marker + "-", color=color, label=f"{LABELS.get(m, m)}: slope {p_t:.2f}")
        ax2.loglog(wall, e, "x--", color=color, lw=0.8, alpha=0.6)
    # reference slope 2
    h_all = sorted({1e3 * float(r["h_m"]) for r in rows})
    e_min = min(float(r["relative_error"]) for r in rows)
    ax1.loglog([h_all[0], h_all[0] * 4], [e_min / 2, e_min / 2 * 16], "k-", lw=0.8)
    ax1.annotate("slope 2", (h_all[0] * 2, e_min / 2 * 4), fontsize=8, ha="right")
    ax1.set_xlabel("element size / particle spacing h (mm)")
    ax1.set_ylabel("L2 displacement error / RMS amplitude")
    ax1.set_title("error against spacing (slopes: 3 finest)")
    ax2.set_xlabel("wall time, 1 rank (s): time loop (solid), whole run (dashed)")
    ax2.set_ylabel("L2 displacement error / RMS amplitude")
    ax2.set_title("work-precision (slopes: time loop, 3 finest)")
    for ax in (ax1, ax2):
        ax.grid(alpha=0.3, which="both")
        ax.legend(fontsize=7)
    fig.suptitle("3-D standing wave in a steel cube on rollers, t = 9T/8 (prm/verification/standing_wave)")
    fig.tight_layout()
    fig.savefig(png, dpi=110)
    print("wrote", png)
    for m in methods:
        print(f"{m}: rate against h {rates[m][0]:.2f}, against time-loop wall time {rates[m][1]:.2f}")

    if len(sys.argv) > 3:
        lines = ["Measured with `contrib/convergence` (1 MPI rank; relative error = L2 error / (U sqrt(3/8)),",
                 "the RMS of the exact displacement at its peak; time loop = wall time without set-up and output)."]
        if "hybrid" in methods:
            lines += ["hybrid: FE cube whose elements with centre in [25, 75]^3 mm (the central 1/8) are particles from",
                      "the set-up; nodes counts FE nodes and particles together (interface points once)."]
        lines += ["",
                 "| method | cells per edge | h (mm) | nodes | steps | L2 error (m) | relative error | local rate | time loop (s) | whole run (s) |",
                 "|---|---|---|---|---|---|---|---|---|---|"]
        for m in methods:
            prev = None
            for r in runs[m]:
                h, e = float(r["h_m"]), float(r["l2_error_m"])
                local = f"{math.log(prev[1] / e) / math.log(prev[0] / h):.2f}" if prev else "-"
                prev = (h, e)
                lines.append(f"| {m} | {r['cells_per_edge']} | {1e3 * h:.4g} | {r['n_nodes']} | {r['steps']} | {e:.3e} | "
                             f"{float(r['relative_error']):.4f} | {local} | {float(r['loop_time_s']):.2f} | "
                             f"{float(r['wall_time_s']):.2f} |")
        lines += ["", "| method | rate against h (3 finest) | slope against time-loop wall time (3 finest) |", "|---|---|---|"]
        for m in methods:
            lines.append(f"| {m} | {rates[m][0]:.2f} | {rates[m][1]:.2f} |")
        lines += ["", "![Standing wave: error against spacing and against wall time](benchmarks/convergence.png)"]
        if replace_marked(sys.argv[3], "CONVERGENCE", lines, add=False):
            print("updated", sys.argv[3])


if __name__ == "__main__":
    main()
