#!/usr/bin/env python3
# SPDX-License-Identifier: LGPL-2.1-or-later
"""Summarise contrib/weak_scaling runs (issue 28): step work, traffic and memory per rank.

weak_scaling_report.py OUT CSV MD [PNG]
OUT holds np<P>/ directories with summary.json (and, from older runs, rss_<pid>.txt: the peak RSS
of each rank in KB from GNU time). Per rank count P:
- step CPU per rank per step: phases 1-9 of phase_cpu_time_by_rank_s over the steps, the largest
  and the median rank (CPU time: what an oversubscribed machine can measure);
- growth: the largest rank's step CPU over the 1-rank figure (issue 28 asks <= 1.15 at 8 ranks);
- bytes sent per step: the largest rank, per exchange point and in total (bytes_sent_per_step_by_rank);
- set-up CPU per rank (phase 0, largest) and summed over the ranks;
- peak RSS per rank (largest; memory_by_rank_bytes "peak resident").
Writes CSV and the table between <!-- WEAK SCALING BEGIN --> and <!-- WEAK SCALING END --> of MD;
with PNG (and matplotlib) the figure: step CPU per step by phase, and bytes sent per rank and step
by exchange point, against the rank count.
"""
import glob
import json
import os
import statistics
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from doc_tables import commit_of, machine, replace_marked  # noqa: E402

out, csv_path, md_path = sys.argv[1:4]
png_path = sys.argv[4] if len(sys.argv) > 4 else None
rows = []
for d in sorted(glob.glob(os.path.join(out, "np*")), key=lambda p: int(os.path.basename(p)[2:]) if
                os.path.basename(p)[2:].isdigit() else 0):
    if not os.path.isdir(d):
        continue
    s = json.load(open(os.path.join(d, "summary.json")))
    cpu = s["phase_cpu_time_by_rank_s"]
    steps = s["steps"]
    step_cpu = [sum(r[1:10]) / steps for r in cpu]
    traffic = s["bytes_sent_per_step_by_rank"]
    total = [sum(v[r] for v in traffic.values()) for r in range(len(cpu))]
    # Peak RSS per rank (MB): summary.json, or rss_<pid>.txt files of GNU time (KB) if present.
    rss = [b / 2**20 for b in s.get("memory_by_rank_bytes", {}).get("peak resident", [])]
    for f in glob.glob(os.path.join(d, "rss_*.txt")):
        lines = [x for x in open(f).read().split() if x.isdigit()]
        if lines:
            rss.append(int(lines[-1]) / 1024.)
    rows.append({
        "ranks": s["n_mpi_ranks"], "elements": s["n_elements"], "particles": s["n_particles"], "steps": steps,
        "step_cpu_max_ms": 1e3 * max(step_cpu), "step_cpu_median_ms": 1e3 * statistics.median(step_cpu),
        "bytes_per_step_max": max(total),
        **{f"bytes {k} max": max(v) for k, v in traffic.items()},
        "setup_cpu_max_s": max(r[0] for r in cpu), "setup_cpu_sum_s": sum(r[0] for r in cpu),
        "peak_rss_max_mb": max(rss) if rss else float("nan"),
        # Per phase 1-9: the CPU time per step (ms) of the rank with the largest step CPU.
        **{f"phase {p} ms": 1e3 * cpu[step_cpu.index(max(step_cpu))][p] / steps for p in range(1, 10)},
    })
if not rows:
    sys.exit("weak_scaling_report.py: no runs in " + out)
base = rows[0]["step_cpu_max_ms"]
keys = list(rows[0].keys())  # (the per-phase keys are in the CSV too)
with open(csv_path, "w") as f:
    f.write(",".join(keys + ["step_cpu_growth"]) + "\n")
    for r in rows:
        f.write(",".join(f"{r.get(k, '')}" for k in keys) + f",{r['step_cpu_max_ms'] / base:.3f}\n")
names = [k for k in keys if k.startswith("bytes ") and k.endswith(" max")]
md = [f"Measured with `contrib/weak_scaling` at {commit_of(md_path)} on {machine()}, one thread per rank, "
      "oversubscribed beyond 2 ranks; largest rank unless noted.", "",
      "| ranks | elements | particles | step CPU per rank per step (ms), largest / median | growth | "
      "bytes sent per step (kB): " + ", ".join(n[6:-4] for n in names) + " | set-up CPU largest / summed (s) | "
      "peak RSS (MB) |",
      "|---|---|---|---|---|---|---|---|"]
for r in rows:
    md.append(f"| {r['ranks']} | {r['elements']} | {r['particles']} | {r['step_cpu_max_ms']:.1f} / "
              f"{r['step_cpu_median_ms']:.1f} | {r['step_cpu_max_ms'] / base:.2f} | "
              + ", ".join(f"{r[n] / 1e3:.1f}" for n in names)
              + f" | {r['setup_cpu_max_s']:.1f} / {r['setup_cpu_sum_s']:.1f} | {r['peak_rss_max_mb']:.0f} |")
PHASES = ["1 step size", "2 drift", "3 exchange", "4 topology", "5 FE force", "6 particle force", "7 loads",
          "8 accumulate", "9 kick"]
md += ["", "Step CPU per step by phase (ms) of the rank with the largest step CPU:", "",
       "| ranks | " + " | ".join(PHASES) + " |", "|---" * (len(PHASES) + 1) + "|"]
for r in rows:
    md.append(f"| {r['ranks']} | " + " | ".join(f"{r[f'phase {p} ms']:.1f}" for p in range(1, 10)) + " |")
replace_marked(md_path, "WEAK SCALING", md)
print("\n".join(md))

if png_path:
    try:
        import matplotlib
        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        print("weak_scaling_report.py: no matplotlib, no figure")
        sys.exit(0)
    ranks = [r["ranks"] for r in rows]
    x = list(range(len(rows)))
    fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(11, 4.2))
    bottom = [0.] * len(rows)
    for k, name in enumerate(PHASES):
        h = [r[f"phase {k + 1} ms"] for r in rows]
        if max(h) < 0.5:
            continue
        ax1.bar(x, h, bottom=bottom, label=name, color=f"C{k}")
        bottom = [b + v for b, v in zip(bottom, h)]
    ax1.axhline(1.15 * rows[0]["step_cpu_max_ms"], color="k", ls="--", lw=1, label="1 rank + 15 % (issue 28)")
    ax1.set_xticks(x, [str(n) for n in ranks])
    ax1.set_xlabel("ranks (one unit of 25 200 hexahedra + 27 869 particles each)")
    ax1.set_ylabel("step CPU per step, slowest rank (ms)")
    ax1.set_ylim(0, 1.45 * max(bottom))
    ax1.legend(fontsize=7, loc="upper left", ncol=3)
    # One rank sends nothing: the curves start at 2 ranks.
    many = [r for r in rows if r["ranks"] > 1]
    for n in names:
        ax2.plot([r["ranks"] for r in many], [r[n] / 1e3 for r in many], "o-", label=n[6:-4])
    ax2.set_xscale("log", base=2)
    ax2.set_yscale("log")
    ax2.set_xticks([r["ranks"] for r in many], [str(r["ranks"]) for r in many])
    ax2.set_xlabel("ranks")
    ax2.set_ylabel("bytes sent per step, largest rank (kB)")
    ax2.legend(fontsize=7)
    ax2.grid(True, which="both", alpha=0.3)
    fig.suptitle("Weak scaling (contrib/weak_scaling): what grows with the rank count", fontsize=10)
    fig.tight_layout()
    fig.savefig(png_path, dpi=110)
    print("wrote " + png_path)
