#!/usr/bin/env python3
# SPDX-License-Identifier: LGPL-2.1-or-later
"""Wave crossing FE -> particles -> FE (prm/verification/wave_crossing/wave_crossing.prm) against
the FE-only bar (wave_crossing_fe.prm).

Usage: plot_wave_crossing.py HYBRID_DIR FE_DIR PNG CSV

Reads history.csv (time, v_in, v_mid, v_probe, ke_left, ke_particles, ke_right, boundary_work)
and summary.json of both runs. The PNG has two panels: velocity at x = 0.05, 0.15 and 0.25 m
against time, and 2 x the kinetic energy of the segments 0 <= x < 0.1, 0.1 < x < 0.2 and
0.2 < x <= 0.3 divided by the input energy E_in (log scale); hybrid solid, FE-only dashed.
The CSV holds, for each run, the reflected energy fraction at interface 1 (2 ke_left / E_in at
t = 28 us, the pulse inside the middle third) and at interface 2 (2 ke_particles / E_in at
t = 44 us, the pulse past the middle third), the peak velocities at the three probes, the peak
v_probe relative to the FE-only run, the arrival times (first crossing of 5 m/s, half the
amplitude) at x = 0.15 and 0.25 m, the work done by the drive against E_in, the largest
|energy error| from t = 10 us on (as wave_crossing.checks: before, the error is relative to the
small energy of the starting pulse), steps, particles and wall time. In the FE-only run the "reflected" fractions are
what the same segments hold without any interface (dispersion tail of the discrete pulse).
"""
import csv
import json
import os
import sys

import matplotlib
matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

E_IN = 0.22612  # rho c A V^2 3T/8 (header of wave_crossing.prm)
T1, T2 = 28e-6, 44e-6  # sampling times of the reflections at interface 1 and 2
PROBES = [("v_in", "x = 0.05 m (FE)"), ("v_mid", "x = 0.15 m (particles)"), ("v_probe", "x = 0.25 m (FE)")]
SEGMENTS = [("ke_left", "0 <= x < 0.1 (FE)"), ("ke_particles", "0.1 < x < 0.2 (particles)"),
            ("ke_right", "0.2 < x <= 0.3 (FE)")]


def load(directory):
    rows = list(csv.DictReader(open(os.path.join(directory, "history.csv"))))
    data = {k: np.array([float(r[k]) for r in rows]) for k in rows[0]}
    summary = json.load(open(os.path.join(directory, "summary.json")))
    return data, summary


def arrival(data, column, level=5.0):
    """First time (us) the column reaches level (half the pulse amplitude), interpolated."""
    v, t = data[column], data["time"]
    i = int(np.argmax(v >= level))
    return 1e6 * float(t[i - 1] + (level - v[i - 1]) / (v[i] - v[i - 1]) * (t[i] - t[i - 1]))


def at(data, column, t):
    """Linear interpolation of a history column at time t."""
    return float(np.interp(t, data["time"], data[column]))


hybrid_dir, fe_dir, png, out_csv = sys.argv[1:5]
runs = {"hybrid": load(hybrid_dir), "fe_only": load(fe_dir)}

fig, (ax1, ax2) = plt.subplots(2, 1, figsize=(9, 9.5), sharex=True)
for run, ls in (("hybrid", "-"), ("fe_only", "--")):
    data, _ = runs[run]
    t = 1e6 * data["time"]
    name = "hybrid" if run == "hybrid" else "FE only"
    for i, (col, label) in enumerate(PROBES):
        ax1.plot(t, data[col], color=f"C{i}", ls=ls, lw=1.2, label=f"{name}, {label}")
    for i, (col, label) in enumerate(SEGMENTS):
        y = 2 * data[col] / E_IN
        ax2.plot(t, np.where(y > 0, y, np.nan), color=f"C{i}", ls=ls, lw=1.2, label=f"{name}, {label}")
ax1.axhline(10, color="gray", ls=":", lw=0.8)
ax1.annotate("V = 10 m/s", (1, 10), fontsize=7, color="gray", va="bottom")
ax1.set_ylabel("velocity v_x (m/s)")
ax1.legend(fontsize=7, ncol=2)
ax1.grid(alpha=0.3)
for t_sample, what in ((T1, "interface 1 reflection"), (T2, "interface 2 reflection")):
    for ax in (ax1, ax2):
        ax.axvline(1e6 * t_sample, color="gray", ls=":", lw=0.8)
    ax2.annotate(f"{1e6 * t_sample:g} us: {what}", (1e6 * t_sample, 2e-10), fontsize=7, color="gray",
                 rotation=90, ha="right", va="bottom")
ax2.set_yscale("log")
ax2.set_ylim(1e-10, 3)
ax2.set_xlabel("time (us)")
ax2.set_ylabel("2 KE(segment) / E_in")
ax2.legend(fontsize=7, ncol=2, loc="upper center", bbox_to_anchor=(0.5, -0.13))
ax2.grid(alpha=0.3, which="both")
fig.suptitle("Wave crossing FE -> particles -> FE, steel bar on rollers, 10 m/s sin^2 pulse\n"
             "(prm/verification/wave_crossing): hybrid solid, FE only dashed", fontsize=10)
fig.tight_layout()
fig.savefig(png, dpi=120)
print("wrote", png)

fields = ["run", "reflected_interface1", "reflected_interface2", "peak_v_in_m_s", "peak_v_mid_m_s",
          "peak_v_probe_m_s", "peak_v_probe_vs_fe_only", "arrival_v_mid_us",
          "arrival_v_probe_us", "boundary_work_over_e_in", "max_abs_energy_error_after_10us",
          "steps", "n_particles", "wall_time_s"]
peak_fe = float(np.max(runs["fe_only"][0]["v_probe"]))
with open(out_csv, "w", newline="") as f:
    w = csv.DictWriter(f, fieldnames=fields, lineterminator="\n")
    w.writeheader()
    for run, (data, s) in runs.items():
        peak = float(np.max(data["v_probe"]))
        row = {"run": run,
               "reflected_interface1": f"{2 * at(data, 'ke_left', T1) / E_IN:.3e}",
               "reflected_interface2": f"{2 * at(data, 'ke_particles', T2) / E_IN:.3e}",
               "peak_v_in_m_s": f"{np.max(data['v_in']):.4f}", "peak_v_mid_m_s": f"{np.max(data['v_mid']):.4f}",
               "peak_v_probe_m_s": f"{peak:.4f}", "peak_v_probe_vs_fe_only": f"{peak / peak_fe:.5f}",
               "arrival_v_mid_us": f"{arrival(data, 'v_mid'):.3f}", "arrival_v_probe_us": f"{arrival(data, 'v_probe'):.3f}",
               "boundary_work_over_e_in": f"{data['boundary_work'][-1] / E_IN:.5f}",
               "max_abs_energy_error_after_10us":
                   f"{np.max(np.abs(data['energy_error'][data['time'] >= 1e-5])):.2e}", "steps": s["steps"],
               "n_particles": s.get("n_particles", 0), "wall_time_s": f"{s['wall_time_s']:.1f}"}
        w.writerow(row)
print(open(out_csv).read(), end="")
print("wrote", out_csv)
