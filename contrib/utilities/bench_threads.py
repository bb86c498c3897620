#!/usr/bin/env python3
# SPDX-License-Identifier: LGPL-2.1-or-later
"""Speed-up of threads inside one MPI rank (doc/performance.md, "Threads").

Runs prm/benchmarks/block/block.prm as FE (von Mises, 103 823 hexahedra) and as particles
(elastic, 110 592 particles) at each thread count of THREADS (`shard run --threads N`),
interleaved (run i of every case and count before run i + 1), RUNS times each, and prints the
medians (with the range) of the step phases 1-9 (phase_time_s of summary.json without phase 0
set-up and phase 10 record) and of the force phase, and the speed-up against the first count.
With --baseline BIN (e.g. main's build/bin/shard) that binary runs too, at one thread, in the
same interleaved series: the ratio of its 1-thread time to this build's checks for a regression.
On a machine shared with other work the medians mix in the load of the others; the ratio of the
fastest runs ("speed-up, fastest runs") is closer to what a quiet machine gives.

Usage: contrib/utilities/bench_threads.py [--build DIR] [--runs N] [--steps N] [--threads 1 2]
                                          [--baseline BIN] [--cases fe particles]
"""
import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile

root = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
ap.add_argument("--build", default=os.path.join(root, "build"))
ap.add_argument("--runs", type=int, default=3)
ap.add_argument("--steps", type=int, default=100, help="steps per run (block.prm has 200)")
ap.add_argument("--threads", type=int, nargs="+", default=[1, 2])
ap.add_argument("--baseline", help="a second shard binary, run at one thread (no --threads option)")
ap.add_argument("--cases", nargs="+", default=["fe", "particles"], choices=["fe", "particles"])
args = ap.parse_args()

shard = os.path.join(args.build, "bin", "shard")
scene = os.path.join(root, "prm", "benchmarks", "block", "block.prm")
work = tempfile.mkdtemp(prefix="shard_bench_threads_")
cases = {"fe": ("5 FE force", ["--set", "B - Mesh/block/material=plastic"]),
         "particles": ("6 particle force", ["--set", "E - Particles/bodies=block",
                                            "--set", "B - Mesh/block/material=elastic"])}
variants = [(f"{n} thread{'s' if n > 1 else ''}", shard, ["--threads", str(n)]) for n in args.threads]
if args.baseline:
    variants.append(("baseline, 1 thread", args.baseline, []))

results = {(c, v[0]): [] for c in args.cases for v in variants}
env = dict(os.environ, DEAL_II_NUM_THREADS="1", OMPI_ALLOW_RUN_AS_ROOT="1", OMPI_ALLOW_RUN_AS_ROOT_CONFIRM="1")
for i in range(args.runs):
    for case in args.cases:
        force, sets = cases[case]
        for label, binary, extra in variants:
            out = os.path.join(work, "out")
            cmd = [binary, "run", scene, *sets, "--set", f"J - Time integration/max steps={args.steps}",
                   "--set", "K - Output/interval=0", "--set", "K - Output/directory=" + out, *extra]
            p = subprocess.run(cmd, capture_output=True, text=True, env=env)
            if p.returncode != 0:
                sys.exit(f"bench_threads: run failed ({p.returncode}): {' '.join(cmd)}\n{p.stderr}")
            summary = json.load(open(os.path.join(out, "summary.json")))
            times = summary["phase_time_s"]
            step = sum(t for k, t in times.items() if not k.startswith(("0 ", "10 ")))
            results[(case, label)].append({"step": step, "force": times.get(force, 0.),
                                           "threads": summary.get("n_threads", 1)})
            print(f"run {i + 1}: {case:9s} {label:20s} step phases {step:7.3f} s, {force} {times.get(force, 0.):7.3f} s",
                  file=sys.stderr, flush=True)


def med_range(xs):
    return f"{statistics.median(xs):.3f} ({min(xs):.3f} to {max(xs):.3f})"


print(f"\n{args.runs} interleaved runs, {args.steps} steps each; seconds, medians (range)\n")
print("| case | variant | step phases 1-9 (s) | force phase (s) | speed-up, step phases | speed-up, force phase "
      "| speed-up, fastest runs |")
print("|---|---|---|---|---|---|---|")
for case in args.cases:
    ref = results[(case, variants[0][0])]
    ref_step = statistics.median(r["step"] for r in ref)
    ref_force = statistics.median(r["force"] for r in ref)
    ref_fastest = min(r["step"] for r in ref)
    for label, _, _ in variants:
        rows = results[(case, label)]
        step = [r["step"] for r in rows]
        force = [r["force"] for r in rows]
        print(f"| {case} | {label} | {med_range(step)} | {med_range(force)} | "
              f"**{ref_step / statistics.median(step):.2f}** | {ref_force / statistics.median(force):.2f} | "
              f"{ref_fastest / min(step):.2f} |")
    # Per-run ratios of the series (run i of each variant ran back to back).
    for label, _, _ in variants[1:]:
        ratios = [a["step"] / b["step"] for a, b in zip(ref, results[(case, label)])]
        print(f"  {case}, {variants[0][0]} / {label} per run: {', '.join(f'{x:.2f}' for x in ratios)}")
