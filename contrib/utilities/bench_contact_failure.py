#!/usr/bin/env python3
# SPDX-License-Identifier: LGPL-2.1-or-later
"""Cost of contact and bond failure in the perforation example (doc/performance.md).

Runs prm/examples/plate_perforation.prm in three variants, interleaved, RUNS times each:
"none" (no H - Contact, bond criterion none), "contact only" (criterion none) and the full
scene, and prints per-step medians of the phases (phase_time_s of summary.json over the steps;
set-up and record excluded) and the ratios to "none".

Usage: contrib/utilities/bench_contact_failure.py [BUILD_DIR] [RUNS]   (defaults: build, 5)
"""
import json
import os
import re
import statistics
import subprocess
import sys
import tempfile

root = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
build = sys.argv[1] if len(sys.argv) > 1 else os.path.join(root, "build")
runs = int(sys.argv[2]) if len(sys.argv) > 2 else 5
shard = os.path.join(build, "bin", "shard")
scene = os.path.join(root, "prm", "examples", "plate_perforation.prm")
work = tempfile.mkdtemp(prefix="shard_bench_cf_")
text = open(scene).read()
no_bonds = text.replace("set criterion = plastic strain", "set criterion = none")
variants = {
    "none": re.sub(r"subsection H - Contact.*?\nend\n", "", no_bonds, flags=re.S),
    "contact only": no_bonds,
    "contact and bond failure": text,
}
files = {}
for name, content in variants.items():
    files[name] = os.path.join(work, name.replace(" ", "_") + ".prm")
    open(files[name], "w").write(content)

phases = {"topology": "4 topology", "FE force": "5 FE force", "particle force": "6 particle force",
          "loads": "7 loads"}
results = {name: [] for name in variants}
for _ in range(runs):
    for name, prm in files.items():
        out = os.path.join(work, "out")
        subprocess.run([shard, "run", prm, "--set", "K - Output/interval=0", "--set", "K - Output/directory=" + out,
                        "--set", "K - Output/fragment plots=false"], check=True, capture_output=True)
        summary = json.load(open(os.path.join(out, "summary.json")))
        times, steps = summary["phase_time_s"], summary["steps"]
        row = {"steps": steps,
               "step": 1e3 * sum(t for k, t in times.items() if not k.startswith(("0 ", "10 "))) / steps}
        for label, key in phases.items():
            row[label] = 1e3 * times.get(key, 0.) / steps
        results[name].append(row)

print("| variant | steps | step | 4 topology | 5 FE force | 6 particle force | 7 loads (contact) | vs none |")
print("|---|---|---|---|---|---|---|---|")
base = statistics.median(r["step"] for r in results["none"])
for name, rows in results.items():
    med = {k: statistics.median(r[k] for r in rows) for k in rows[0]}
    print(f"| {name} | {med['steps']:.0f} | {med['step']:.2f} | {med['topology']:.2f} | {med['FE force']:.2f} | "
          f"{med['particle force']:.2f} | {med['loads']:.2f} | {med['step'] / base:.2f} |")
    share = (med["topology"] + med["loads"]) / (med["step"] - med["topology"] - med["loads"])
    print(f"  {name}: runs {[round(r['step'], 2) for r in rows]} ms; topology + loads over the other phases {share:.3f}")
