#!/usr/bin/env python3
# SPDX-License-Identifier: LGPL-2.1-or-later
"""Summarise contrib/bench runs: medians (min, max) per material; CSV and a Markdown table
inserted into doc/performance.md between <!-- BENCH BEGIN --> and <!-- BENCH END -->."""
import datetime
import glob
import json
import os
import re
import statistics
import subprocess
import sys

out, csv_path, md_path = sys.argv[1:4]
groups = {}
for f in sorted(glob.glob(os.path.join(out, "*", "summary.json"))):
    name = os.path.basename(os.path.dirname(f)).rsplit("_", 1)[0].replace("_", " ")
    groups.setdefault(name, []).append(json.load(open(f)))

cpu = "unknown CPU"
try:
    for line in open("/proc/cpuinfo"):
        if line.startswith("model name"):
            cpu = line.split(":", 1)[1].strip()
            break
except OSError:
    pass
try:
    commit = subprocess.run(["git", "-C", os.path.dirname(md_path), "rev-parse", "--short", "HEAD"],
                            capture_output=True, text=True).stdout.strip()
except OSError:
    commit = "unknown"

phases = ["5 FE force", "2 drift", "3 exchange", "8 accumulate", "9 kick", "10 record"]
rows, lines = [], []
header = ("material,elements,steps,runs,element_steps_per_s_median,min,max,us_per_element_step_median,"
          + ",".join(f"{p.split(' ', 1)[1].replace(' ', '_')}_s_median" for p in phases))
for name, runs in groups.items():
    eps = [r["element_steps_per_s"] for r in runs]
    us = [r["us_per_element_step"] for r in runs]
    ph = [statistics.median(r["phase_time_s"][p] for r in runs) for p in phases]
    rows.append(f"{name},{runs[0]['n_elements']},{runs[0]['steps']},{len(runs)},{statistics.median(eps):.4g},"
                f"{min(eps):.4g},{max(eps):.4g},{statistics.median(us):.4f}," + ",".join(f"{x:.4g}" for x in ph))
    lines.append(f"| {name} | {runs[0]['n_elements']} | {runs[0]['steps']} | {len(runs)} | "
                 f"{statistics.median(eps):.3g} ({min(eps):.3g} to {max(eps):.3g}) | "
                 f"**{statistics.median(us):.3f}** | " + " | ".join(f"{x:.3f}" for x in ph) + " |")
with open(csv_path, "w") as f:
    f.write(header + "\n" + "\n".join(rows) + "\n")

table = [f"Measured {datetime.date.today()} on {cpu}, 1 MPI rank, 1 thread, commit {commit}; "
         f"medians of the runs (range in parentheses).", "",
         "| material | elements | steps | runs | element-steps/s | us per element-step (phase 5) | "
         + " | ".join(f"{p} (s)" for p in phases) + " |",
         "|---" * (6 + len(phases)) + "|"] + lines
text = open(md_path).read() if os.path.exists(md_path) else "<!-- BENCH BEGIN -->\n<!-- BENCH END -->\n"
text = re.sub(r"<!-- BENCH BEGIN -->.*<!-- BENCH END -->",
              "<!-- BENCH BEGIN -->\n" + "\n".join(table) + "\n<!-- BENCH END -->", text, flags=re.S)
open(md_path, "w").write(text)
print("\n".join(table))
