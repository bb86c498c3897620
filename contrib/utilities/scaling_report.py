#!/usr/bin/env python3
# SPDX-License-Identifier: LGPL-2.1-or-later
"""Summarise contrib/scaling runs: speed-up from 1 to 2 MPI ranks, per-rank phases, imbalance.

scaling_report.py OUT CSV MD
OUT holds <variant>_<i> directories (variant np1, np2, np2-cellcount) with summary.json. The step
time of a run is the largest over the ranks of the sum of phases 1-9 (phase_time_by_rank_s; set-up
and record excluded). Speed-up = step time at 1 rank / step time at 2 ranks, per round i of the
interleaved runs; the table gives the median and range of those ratios. Writes CSV and the table
between <!-- SCALING BEGIN --> and <!-- SCALING END --> of MD.
"""
import datetime
import glob
import json
import os
import statistics
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from doc_tables import commit_of, machine, replace_marked  # noqa: E402

out, csv_path, md_path = sys.argv[1:4]
runs = {}
for f in sorted(glob.glob(os.path.join(out, "*", "summary.json"))):
    variant, _, i = os.path.basename(os.path.dirname(f)).rpartition("_")
    runs.setdefault(variant, {})[int(i)] = json.load(open(f))
med = statistics.median
STEP = ["1 step size", "2 drift", "3 exchange", "4 topology", "5 FE force", "6 particle force", "7 loads",
        "8 accumulate", "9 kick"]
NAMES = ["0 set-up"] + STEP + ["10 record"]


def rank_phases(r):
    """Per rank: dict phase -> seconds."""
    return [dict(zip(NAMES, times)) for times in r["phase_time_by_rank_s"]]


def step_time(r):
    return max(sum(p[n] for n in STEP) for p in rank_phases(r))


WORK = [n for n in STEP if n not in ("3 exchange", "8 accumulate")]


def rank_cpu(r):
    """Per rank: dict phase -> CPU seconds of the main thread (phase_cpu_time_by_rank_s)."""
    return [dict(zip(NAMES, times)) for times in r.get("phase_cpu_time_by_rank_s", [])]


def cpu_step(r):
    """CPU time of the slowest rank: its work phases plus the smallest exchange CPU time of any
    rank (an upper bound of the messages; the rest of 3 + 8 is waiting, spun or slept)."""
    c = rank_cpu(r)
    if not c:
        return float("nan")
    comm = min(p["3 exchange"] + p["8 accumulate"] for p in c)
    return max(sum(p[n] for n in WORK) for p in c) + comm


def cpu_work(r):
    c = rank_cpu(r)
    return max(sum(p[n] for n in WORK) for p in c) if c else float("nan")


def share(r, names):
    """Largest share over ranks of the phases `names` in that rank's step time."""
    return max(sum(p[n] for n in names) / sum(p[n] for n in STEP) for p in rank_phases(r))


def force_imbalance(r):
    """max / mean over ranks of the force phases 5 + 6 (the measured work imbalance)."""
    w = [p["5 FE force"] + p["6 particle force"] for p in rank_phases(r)]
    return max(w) / (sum(w) / len(w))


def stats(xs):
    return (med(xs), min(xs), max(xs)) if xs else (float("nan"),) * 3


def fmt(s, f="{:.3f}"):
    m, lo, hi = s
    return f"{f.format(m)} ({f.format(lo)} to {f.format(hi)})" if m == m else "-"


commit = commit_of(md_path)
cpu = machine()
base = runs.get("np1", {})
any_run = next((r for v in runs.values() for r in v.values()), {})
phases = {}
rows, csv_rows = [], ["variant,ranks,runs,elements,particles,steps,step_s_median,min,max,speed_up_median,min,max,"
                      "exchange_share_median,force_imbalance_median,work_imbalance,work_imbalance_cell_count,"
                      "elements_per_rank,particles_per_rank"]
for variant in sorted(runs, key=lambda v: ["np1", "np2", "np2-cellcount"].index(v) if v in
                      ["np1", "np2", "np2-cellcount"] else 9):
    rs = runs[variant]
    r0 = next(iter(rs.values()))
    st = stats([step_time(r) for r in rs.values()])
    sp = stats([step_time(base[i]) / step_time(r) for i, r in rs.items() if i in base])
    ex = stats([share(r, ["3 exchange", "8 accumulate"]) for r in rs.values()])
    cs = stats([cpu_step(base[i]) / cpu_step(r) for i, r in rs.items() if i in base])
    cw = stats([cpu_work(base[i]) / cpu_work(r) for i, r in rs.items() if i in base])
    cpu_cols = f"{fmt(cs)} | {fmt(cw)} |"
    fi = stats([force_imbalance(r) for r in rs.values()])
    part = r0.get("partition", {})
    epr = "/".join(f"{x:.0f}" for x in part.get("elements_per_rank", []))
    ppr = "/".join(f"{x:.0f}" for x in part.get("particles_per_rank", []))
    wi, wc = part.get("work_imbalance", float("nan")), part.get("work_imbalance_cell_count", 0)
    ranks = r0["n_mpi_ranks"]
    rows.append(f"| {variant} | {ranks} | {len(rs)} | {fmt(st, '{:.2f}')} | {fmt(sp)} | {cpu_cols} {fmt(ex, '{:.3f}')} | "
                f"{fmt(fi)} | {wi:.3f} | {epr} | {ppr} |")
    csv_rows.append(f"{variant},{ranks},{len(rs)},{r0['n_elements'] - r0['n_converted_elements']},"
                    f"{r0['n_particles']},{r0['steps']},{st[0]:.4g},{st[1]:.4g},{st[2]:.4g},{sp[0]:.4g},{sp[1]:.4g},"
                    f"{sp[2]:.4g},{cs[0]:.4g},{cs[1]:.4g},{cs[2]:.4g},{ex[0]:.4g},{fi[0]:.4g},{wi:.4g},{wc:.4g},{epr},{ppr}")
    if variant != "np1":
        # Phases per rank, medians over the runs.
        phases[variant] = [[med(rank_phases(r)[k][n] for r in rs.values()) for n in STEP] for k in range(ranks)]
        if all(rank_cpu(r) for r in rs.values()):
            phases[variant + ", CPU time"] = [[med(rank_cpu(r)[k][n] for r in rs.values()) for n in STEP]
                                              for k in range(ranks)]
with open(csv_path, "w") as f:
    f.write("\n".join(csv_rows) + "\n")

stamp = (f"Measured {datetime.date.today()} on {cpu}, commit {commit} (binary: shard "
         f"{any_run.get('shard_version', '')}), 1 thread per rank, "
         f"{any_run.get('n_elements', 0) - any_run.get('n_converted_elements', 0)} elements and "
         f"{any_run.get('n_particles', 0)} particles, {any_run.get('steps', 0)} steps; medians of the interleaved "
         "rounds (range in parentheses).")
t = [stamp, "",
     "| variant | ranks | runs | step time, phases 1-9 (s) | speed-up vs 1 rank (wall) | "
     "speed-up, CPU time (work + least exchange) | speed-up, CPU time (work phases only) | "
     "exchange share (3 + 8, wall) | force imbalance (5 + 6 wall, max/mean) | work imbalance (model) | "
     "elements per rank | particles per rank |",
     "|---" * 12 + "|"] + rows
for variant in phases:
    t += ["", f"Phases per rank, {variant} (s, medians):", "",
          "| rank | " + " | ".join(STEP) + " |", "|---" * (1 + len(STEP)) + "|"]
    for k, p in enumerate(phases[variant]):
        t.append(f"| {k} | " + " | ".join(f"{x:.3f}" for x in p) + " |")
replace_marked(md_path, "SCALING", t)
print("\n".join(t))
