#!/usr/bin/env python3
# SPDX-License-Identifier: LGPL-2.1-or-later
"""Summarise contrib/bench runs: medians (min, max) per method and material.

bench_report.py OUT FE_CSV MD [PARTICLE_CSV]
OUT holds one directory per run, <method>_<material>_<i> (method fe or particles; older
<material>_<i> directories count as fe), each with a summary.json. Writes the FE rows to FE_CSV
and the Markdown table between <!-- BENCH BEGIN --> and <!-- BENCH END --> of MD; with particle
runs, also PARTICLE_CSV (default: bench_particles.csv beside FE_CSV) and the particle tables
between <!-- PARTICLE BENCH BEGIN --> and <!-- PARTICLE BENCH END -->.

Particle cost per particle-step: phase 6 (particle force) / (particles x steps). The comparison
with the elements at the same spacing is per node: the wall time of the step phases 1-9 (all
but set-up and record) divided by (nodes x steps) for the FE run and by (particles x steps) for
the particle run (one particle per node), and the same for the force phase alone (5 or 6).
"""
import datetime
import glob
import json
import os
import re
import statistics
import subprocess
import sys

out, csv_path, md_path = sys.argv[1:4]
pcsv_path = sys.argv[4] if len(sys.argv) > 4 else os.path.join(os.path.dirname(csv_path), "bench_particles.csv")
groups = {}
for f in sorted(glob.glob(os.path.join(out, "*", "summary.json"))):
    name = os.path.basename(os.path.dirname(f)).rsplit("_", 1)[0]
    method, _, material = name.partition("_")
    if method not in ("fe", "particles"):
        method, material = "fe", name
    groups.setdefault((method, material.replace("_", " ")), []).append(json.load(open(f)))

cpu = "unknown CPU"
try:
    for line in open("/proc/cpuinfo"):
        if line.startswith("model name"):
            cpu = line.split(":", 1)[1].strip()
            break
except OSError:
    pass
try:
    commit = subprocess.run(["git", "-C", os.path.dirname(os.path.abspath(md_path)), "rev-parse", "--short", "HEAD"],
                            capture_output=True, text=True).stdout.strip() or "unknown"
except OSError:
    commit = "unknown"
version = next((r[0].get("shard_version", "") for r in groups.values()), "")
stamp = (f"Measured {datetime.date.today()} on {cpu}, 1 MPI rank, 1 thread, commit {commit} "
         f"(binary: shard {version}); medians of the runs (range in parentheses).")

med = statistics.median
step_phases = ["1 step size", "2 drift", "3 exchange", "4 topology", "5 FE force", "6 particle force", "7 loads",
               "8 accumulate", "9 kick"]


def step_time(r):
    return sum(r["phase_time_s"].get(p, 0.0) for p in step_phases)


def nodes(r):
    return r["n_dofs"] / 3 if r.get("n_dofs") else None


def fmt_range(xs, f="{:.3g}"):
    return f"{f.format(med(xs))} ({f.format(min(xs))} to {f.format(max(xs))})"


# FE table (unchanged layout).
phases = ["5 FE force", "2 drift", "3 exchange", "8 accumulate", "9 kick", "10 record"]
rows, lines = [], []
header = ("material,elements,steps,runs,element_steps_per_s_median,min,max,us_per_element_step_median,"
          + ",".join(f"{p.split(' ', 1)[1].replace(' ', '_')}_s_median" for p in phases))
fe = {m: runs for (meth, m), runs in groups.items() if meth == "fe"}
for name, runs in fe.items():
    eps = [r["element_steps_per_s"] for r in runs]
    us = [r["us_per_element_step"] for r in runs]
    ph = [med(r["phase_time_s"][p] for r in runs) for p in phases]
    rows.append(f"{name},{runs[0]['n_elements']},{runs[0]['steps']},{len(runs)},{med(eps):.4g},"
                f"{min(eps):.4g},{max(eps):.4g},{med(us):.4f}," + ",".join(f"{x:.4g}" for x in ph))
    lines.append(f"| {name} | {runs[0]['n_elements']} | {runs[0]['steps']} | {len(runs)} | "
                 f"{med(eps):.3g} ({min(eps):.3g} to {max(eps):.3g}) | "
                 f"**{med(us):.3f}** | " + " | ".join(f"{x:.3f}" for x in ph) + " |")
if fe:
    with open(csv_path, "w") as f:
        f.write(header + "\n" + "\n".join(rows) + "\n")
table = [stamp, "",
         "| material | elements | steps | runs | element-steps/s | us per element-step (phase 5) | "
         + " | ".join(f"{p} (s)" for p in phases) + " |",
         "|---" * (6 + len(phases)) + "|"] + lines
text = open(md_path).read() if os.path.exists(md_path) else "<!-- BENCH BEGIN -->\n<!-- BENCH END -->\n"
if fe:
    text = re.sub(r"<!-- BENCH BEGIN -->.*<!-- BENCH END -->",
                  "<!-- BENCH BEGIN -->\n" + "\n".join(table) + "\n<!-- BENCH END -->", text, flags=re.S)
    print("\n".join(table))

# Particle tables.
pt = {m: runs for (meth, m), runs in groups.items() if meth == "particles"}
if pt:
    prow, t1, t2 = [], [], []
    pheader = ("material,particles,steps,runs,particle_steps_per_s_median,min,max,us_per_particle_step_median,min,max,"
               "us_per_particle_step_all_phases_median,fe_us_per_node_step_all_phases_median,"
               "ratio_particle_fe_per_node_all_phases,ratio_particle_fe_per_node_force,bytes_per_particle,"
               "vector_bytes_per_particle,peak_rss_bytes_median,setup_s_median,"
               + ",".join(f"{p.split(' ', 1)[1].replace(' ', '_')}_s_median" for p in step_phases + ["10 record"]))
    phase_cols = ["0 set-up", "5 FE force", "6 particle force", "2 drift", "3 exchange", "7 loads", "8 accumulate",
                  "9 kick", "10 record"]
    for name, runs in pt.items():
        n, steps = runs[0]["n_particles"], runs[0]["steps"]
        ps = [r["particle_steps_per_s"] for r in runs]
        us = [r["us_per_particle_step"] for r in runs]
        us_all = [1e6 * step_time(r) / (r["n_particles"] * r["steps"]) for r in runs]
        bpp = med(r.get("bytes_per_particle", float("nan")) for r in runs)
        vpp = med(3 * r.get("vector_bytes_per_dof", float("nan")) for r in runs)
        rss = med(r.get("peak_rss_bytes", float("nan")) for r in runs)
        ref = fe.get(name)
        if ref:
            nn = nodes(ref[0]) or n
            fe_all = med(1e6 * step_time(r) / (nn * r["steps"]) for r in ref)
            fe_force = med(1e6 * r["phase_time_s"]["5 FE force"] / (nn * r["steps"]) for r in ref)
            ratio_all, ratio_force = med(us_all) / fe_all, med(us) / fe_force
        else:
            nn = fe_all = fe_force = ratio_all = ratio_force = float("nan")
        ph = {p: med(r["phase_time_s"].get(p, 0.0) for r in runs) for p in step_phases + ["0 set-up", "10 record"]}
        prow.append(f"{name},{n},{steps},{len(runs)},{med(ps):.4g},{min(ps):.4g},{max(ps):.4g},{med(us):.4f},"
                    f"{min(us):.4f},{max(us):.4f},{med(us_all):.4f},{fe_all:.4f},{ratio_all:.3f},{ratio_force:.3f},"
                    f"{bpp:.1f},{vpp:.1f},{rss:.4g},{ph['0 set-up']:.4g},"
                    + ",".join(f"{ph[p]:.4g}" for p in step_phases + ["10 record"]))
        t1.append(f"| {name} | {n} | {steps} | {len(runs)} | {fmt_range(ps)} | **{med(us):.3f}** ({min(us):.3f} to "
                  f"{max(us):.3f}) | {med(us_all):.3f} | {fe_all:.3f} ({nn:.0f} nodes) | **{ratio_all:.2f}** "
                  f"({ratio_force:.2f}) | {bpp:.0f} | {vpp:.0f} | {rss / 1e6:.0f} |")
    for (meth, name), runs in sorted(groups.items()):
        t2.append(f"| {meth} | {name} | " + " | ".join(f"{med(r['phase_time_s'].get(p, 0.0) for r in runs):.3f}"
                                                   for p in phase_cols) + " |")
    with open(pcsv_path, "w") as f:
        f.write(pheader + "\n" + "\n".join(prow) + "\n")
    ptable = [stamp, "",
              "| material | particles | steps | runs | particle-steps/s | us per particle-step (phase 6) | "
              "us per particle-step, step phases 1-9 | FE us per node-step, step phases 1-9 | "
              "particle / FE per node, phases 1-9 (force phase only) | bytes per particle (solver) | "
              "distributed vectors, bytes per particle | peak RSS (MB) |",
              "|---" * 12 + "|"] + t1 + [
              "", "Time per phase (s, medians), both methods:", "",
              "| method | material | " + " | ".join(phase_cols) + " |", "|---" * (2 + len(phase_cols)) + "|"] + t2
    if "<!-- PARTICLE BENCH BEGIN -->" not in text:
        text += "\n<!-- PARTICLE BENCH BEGIN -->\n<!-- PARTICLE BENCH END -->\n"
    text = re.sub(r"<!-- PARTICLE BENCH BEGIN -->.*<!-- PARTICLE BENCH END -->",
                  "<!-- PARTICLE BENCH BEGIN -->\n" + "\n".join(ptable) + "\n<!-- PARTICLE BENCH END -->", text,
                  flags=re.S)
    print("\n".join(ptable))
open(md_path, "w").write(text)
