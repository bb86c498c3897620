#!/usr/bin/env python3
# SPDX-License-Identifier: LGPL-2.1-or-later
"""Per-core throughput of two shard binaries, interleaved (rule 4: compare as ratios within one run).

Runs rows of contrib/bench (the 103 823-element block as FE and as particles with the elastic and
the concrete model, the hybrid block, the showcase to 20 us) with the reference binary and the
new one in turn, `--runs` times, one rank and one thread each, and prints per row the median
element-steps/s or particle-steps/s of both and their ratio (new / reference). A refactoring that
must not cost speed (issue 27: "contrib/bench per-core figures are within 3 %") should show
ratios within 0.97 .. 1.03.

    contrib/utilities/bench_compare.py --reference /tmp/shard_ref [--new build/bin/shard] [--runs 3]

Writes nothing into the source tree (runs in output/bench_compare/).
"""
import argparse
import json
import os
import shutil
import statistics
import subprocess
import sys

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
BLOCK = os.path.join(ROOT, "prm", "benchmarks", "block")


def rows(steps):
    m = lambda material: ["--set", f"B - Mesh/block/material={material}", "--set", f"J - Time integration/max steps={steps}"]
    particles = ["--set", "E - Particles/bodies=block"]
    return [
        ("fe_elastic", os.path.join(BLOCK, "block.prm"), m("elastic"), "element_steps_per_s"),
        ("fe_concrete", os.path.join(BLOCK, "block.prm"), m("concrete"), "element_steps_per_s"),
        ("particles_elastic", os.path.join(BLOCK, "block.prm"), m("elastic") + particles, "particle_steps_per_s"),
        ("particles_concrete", os.path.join(BLOCK, "block.prm"), m("concrete") + particles, "particle_steps_per_s"),
        ("hybrid_von_mises", os.path.join(BLOCK, "block_hybrid.prm"),
         ["--set", f"J - Time integration/max steps={steps}"], "particle_steps_per_s"),
        ("showcase", os.path.join(ROOT, "prm", "examples", "showcase.prm"),
         ["--set", "J - Time integration/end time=2e-5", "--set", "K - Output/interval=0",
          "--set", "K - Output/fragment plots=false"], "particle_steps_per_s"),
    ]


def run(binary, prm, extra, out):
    env = dict(os.environ, DEAL_II_NUM_THREADS="1", OMP_NUM_THREADS="1")
    cmd = [binary, "run", prm] + extra + ["--set", f"K - Output/directory={out}", "--set", "K - Output/fields=false"]
    p = subprocess.run(cmd, capture_output=True, text=True, env=env)
    if p.returncode != 0:
        sys.exit(f"bench_compare.py: run failed ({p.returncode}): {' '.join(cmd)}\n{p.stderr[-2000:]}")
    with open(os.path.join(out, "summary.json")) as f:
        return json.load(f)


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--reference", required=True)
    ap.add_argument("--new", default=os.path.join(ROOT, "build", "bin", "shard"))
    ap.add_argument("--runs", type=int, default=3)
    ap.add_argument("--steps", type=int, default=100)
    ap.add_argument("--only", nargs="*", help="row names (default: all)")
    args = ap.parse_args()
    out = os.path.join(ROOT, "output", "bench_compare")
    shutil.rmtree(out, ignore_errors=True)
    table = [r for r in rows(args.steps) if not args.only or r[0] in args.only]
    values = {(name, which): [] for name, *_ in table for which in ("reference", "new")}
    for i in range(args.runs):
        for name, prm, extra, key in table:
            # Alternate which binary goes first, so that a drift in load does not favour one.
            order = [("reference", args.reference), ("new", args.new)]
            if i % 2:
                order.reverse()
            for which, binary in order:
                s = run(os.path.abspath(binary), prm, extra, os.path.join(out, f"{name}_{which}_{i}"))
                values[(name, which)].append(s[key])
                print(f"run {i + 1}/{args.runs} {name:20s} {which:9s} {key} {s[key]:.4g}", flush=True)
    # new/ref: ratio of the medians; paired: median of the ratios of the two runs of one round
    # (they ran back to back, so a slow spell of the machine tends to hit both).
    print(f"\n{'row':20s} {'quantity':22s} {'reference':>12s} {'new':>12s} {'new/ref':>8s} {'paired':>8s}")
    worst = 1.0
    for name, prm, extra, key in table:
        refs, news = values[(name, 'reference')], values[(name, 'new')]
        ref, new = statistics.median(refs), statistics.median(news)
        ratio = new / ref if ref > 0 else float("nan")
        paired = statistics.median(n / r for n, r in zip(news, refs) if r > 0)
        worst = min(worst, ratio)
        print(f"{name:20s} {key:22s} {ref:12.4g} {new:12.4g} {ratio:8.3f} {paired:8.3f}")
    print(f"\nlowest ratio {worst:.3f} (medians of {args.runs} interleaved runs)")


if __name__ == "__main__":
    main()
