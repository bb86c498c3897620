#!/usr/bin/env python3
# SPDX-License-Identifier: LGPL-2.1-or-later
"""Summarise contrib/bench runs: one row per scene, medians (min to max) over the runs.

bench_report.py OUT CSV MD [SECONDS]
OUT holds one directory per run, <row>_<i> (row e.g. fe_elastic, particles_von_mises,
hybrid_von_mises, showcase), each with a summary.json. Writes CSV and, between
<!-- BENCH BEGIN --> and <!-- BENCH END --> of MD, the table, the per-core targets of issue 8
and the time per phase. SECONDS (optional) is the wall time of the whole suite, quoted in MD.

Rates (benchmarks.md 1.4): element-steps/s = element force evaluations / time of phase 5 (FE
force), particle-steps/s = particle force evaluations / time of phase 6; the counts come from
summary.json (element_steps_per_s x phase 5). "Step" is the sum of phases 1-9 (set-up 0 and
record 10 excluded), per element or particle-step when only one kind is present. Memory per
element: HexForce::memory_consumption() (element_bytes) over the elements; per particle:
ParticleSet + SpgForce (particle_bytes) over the particles; the distributed vectors
(vector_bytes_per_dof x 3 per node) and the peak resident set size are separate columns.
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
suite_seconds = float(sys.argv[4]) if len(sys.argv) > 4 else None
ORDER = ["fe_elastic", "fe_von_mises", "fe_concrete", "particles_elastic", "particles_von_mises",
         "particles_concrete", "hybrid_von_mises", "showcase"]
SCENE = {"fe": "block.prm", "particles": "block.prm, bodies=block", "hybrid": "block_hybrid.prm",
         "showcase": "showcase.prm to 20 us"}
groups = {}
for f in sorted(glob.glob(os.path.join(out, "*", "summary.json"))):
    name, _, i = os.path.basename(os.path.dirname(f)).rpartition("_")
    groups.setdefault(name, {})[int(i)] = json.load(open(f))
rows = sorted(groups, key=lambda n: (ORDER.index(n) if n in ORDER else len(ORDER), n))

cpu = machine()
commit = commit_of(md_path)
version = next((r.get("shard_version", "") for g in groups.values() for r in g.values()), "")
n_runs = max((len(g) for g in groups.values()), default=0)
stamp = (f"Measured {datetime.date.today()} on {cpu}, 1 MPI rank, 1 thread, commit {commit} "
         f"(binary: shard {version}), {n_runs} interleaved runs per row"
         + (f", {suite_seconds / 60:.1f} min for the suite" if suite_seconds else "")
         + "; medians of the runs (range in parentheses).")

med = statistics.median
step_phases = ["1 step size", "2 drift", "3 exchange", "4 topology", "5 FE force", "6 particle force", "7 loads",
               "8 accumulate", "9 kick"]
phase_cols = ["0 set-up", "3 exchange", "4 topology", "5 FE force", "6 particle force", "7 loads", "8 accumulate",
              "9 kick", "10 record"]
nan = float("nan")


def ph(r, p):
    return r["phase_time_s"].get(p, 0.0)


def step_time(r):
    return sum(ph(r, p) for p in step_phases)


def element_steps(r):
    return r.get("element_steps_per_s", 0) * ph(r, "5 FE force")


def particle_steps(r):
    return r.get("particle_steps_per_s", 0) * ph(r, "6 particle force")


def stats(xs):
    xs = [x for x in xs if x == x]
    return (med(xs), min(xs), max(xs)) if xs else (nan, nan, nan)


def fmt(s, f="{:.3g}", bold=False):
    m, lo, hi = s
    if m != m:
        return "-"
    core = f.format(m)
    return (f"**{core}**" if bold else core) + (f" ({f.format(lo)} to {f.format(hi)})" if lo != hi else "")


summary = {}
for name in rows:
    runs = list(groups[name].values())
    r0 = runs[0]
    es = [element_steps(r) for r in runs]
    ps = [particle_steps(r) for r in runs]
    steps = r0["steps"]
    n_el = med(es) / steps if med(es) > 0 else 0
    n_p = med(ps) / steps if med(ps) > 0 else 0
    s = {
        "steps": steps,
        "runs": len(runs),
        "elements": n_el,
        "particles": n_p,
        "eps": stats([r["element_steps_per_s"] for r in runs if r.get("element_steps_per_s", 0) > 0]),
        "us_e": stats([r["us_per_element_step"] for r in runs if r.get("us_per_element_step", 0) > 0]),
        "pps": stats([r["particle_steps_per_s"] for r in runs if r.get("particle_steps_per_s", 0) > 0]),
        "us_p": stats([r["us_per_particle_step"] for r in runs if r.get("us_per_particle_step", 0) > 0]),
        "step_ms": stats([1e3 * step_time(r) / r["steps"] for r in runs]),
        "b_e": stats([r.get("element_bytes", nan) / (element_steps(r) / r["steps"]) for r in runs
                      if element_steps(r) > 0]),
        "b_p": stats([r.get("particle_bytes", nan) / (particle_steps(r) / r["steps"]) for r in runs
                      if particle_steps(r) > 0]),
        "b_v": stats([3 * r.get("vector_bytes_per_dof", nan) for r in runs]),
        "rss": stats([r.get("peak_rss_bytes", nan) / 1e6 for r in runs]),
        "phases": {p: med(ph(r, p) for r in runs) for p in step_phases + ["0 set-up", "10 record"]},
        "per_run": groups[name],
    }
    summary[name] = s

# CSV: one line per row.
cols = ["row", "elements", "particles", "steps", "runs", "element_steps_per_s_median", "min", "max",
        "us_per_element_step_median", "min", "max", "particle_steps_per_s_median", "min", "max",
        "us_per_particle_step_median", "min", "max", "ms_per_step_phases_1_9_median", "bytes_per_element",
        "bytes_per_particle", "vector_bytes_per_node", "peak_rss_mb_median"] + \
       [f"{p.split(' ', 1)[1].replace(' ', '_').replace('-', '')}_s_median" for p in ["0 set-up"] + step_phases + ["10 record"]]
lines = [",".join(cols)]
for name in rows:
    s = summary[name]
    vals = [name, f"{s['elements']:.0f}", f"{s['particles']:.0f}", str(s["steps"]), str(s["runs"])]
    for k in ("eps", "us_e", "pps", "us_p"):
        vals += [f"{x:.5g}" for x in s[k]]
    vals += [f"{s['step_ms'][0]:.5g}", f"{s['b_e'][0]:.1f}", f"{s['b_p'][0]:.1f}", f"{s['b_v'][0]:.1f}",
             f"{s['rss'][0]:.1f}"]
    vals += [f"{s['phases'][p]:.4g}" for p in ["0 set-up"] + step_phases + ["10 record"]]
    lines.append(",".join(v.replace("nan", "") for v in vals))
os.makedirs(os.path.dirname(os.path.abspath(csv_path)), exist_ok=True)
with open(csv_path, "w") as f:
    f.write("\n".join(lines) + "\n")

# Markdown table.
t = [stamp, "",
     "| row | scene | elements | particles | steps | element-steps/s | us per element-step (phase 5) | "
     "particle-steps/s | us per particle-step (phase 6) | ms per step (phases 1-9) | bytes per element | "
     "bytes per particle | vector bytes per node | peak RSS (MB) |",
     "|---" * 14 + "|"]
for name in rows:
    s = summary[name]
    kind = name.split("_", 1)[0]
    t.append(f"| {name.replace('_', ' ')} | {SCENE.get(kind, '')} | {s['elements']:.0f} | {s['particles']:.0f} | "
             f"{s['steps']} | {fmt(s['eps'])} | {fmt(s['us_e'], '{:.3f}', True)} | {fmt(s['pps'])} | "
             f"{fmt(s['us_p'], '{:.3f}', True)} | {fmt(s['step_ms'], '{:.1f}')} | {fmt(s['b_e'], '{:.0f}')} | "
             f"{fmt(s['b_p'], '{:.0f}')} | {s['b_v'][0]:.0f} | {s['rss'][0]:.0f} |")


# Per-core targets of issue 8.
def ratio_per_run(a, b, key):
    ra, rb = summary.get(a, {}).get("per_run", {}), summary.get(b, {}).get("per_run", {})
    xs = [ra[i][key] / rb[i][key] for i in ra if i in rb and rb[i].get(key, 0) > 0]
    return stats(xs) if xs else (nan, nan, nan)


def target(label, s, limit, unit):
    m = s[0]
    verdict = "-" if m != m else ("**pass**" if m <= limit else "**FAIL**")
    return f"| {label} | <= {limit:g}{unit} | {fmt(s, '{:.3f}')} | {verdict} |"


t += ["", "Per-core targets of issue 8 (medians over the runs; for the ratio, the median of the run-by-run "
      "ratios of the interleaved runs):", "",
      "| target | limit | measured | result |", "|---|---|---|---|"]
if "fe_von_mises" in summary:
    t.append(target("FE von Mises, us per element-step", summary["fe_von_mises"]["us_e"], 1.0, " us"))
if "particles_elastic" in summary:
    t.append(target("particles elastic, us per particle-step", summary["particles_elastic"]["us_p"], 0.7, " us"))
if "fe_concrete" in summary and "fe_von_mises" in summary:
    t.append(target("K&C / von Mises, FE per element-step", ratio_per_run("fe_concrete", "fe_von_mises",
                                                                          "us_per_element_step"), 2.0, ""))
if "particles_concrete" in summary and "particles_von_mises" in summary:
    s = ratio_per_run("particles_concrete", "particles_von_mises", "us_per_particle_step")
    t.append(f"| K&C / von Mises, particles (not a target) | - | {fmt(s, '{:.3f}')} | - |")

t += ["", "Time per phase (s, medians; 0 set-up and 10 record are outside the step):", "",
      "| row | runs | " + " | ".join(phase_cols) + " |", "|---" * (2 + len(phase_cols)) + "|"]
for name in rows:
    s = summary[name]
    t.append(f"| {name.replace('_', ' ')} | {s['runs']} | " + " | ".join(f"{s['phases'][p]:.3f}" for p in phase_cols)
             + " |")

replace_marked(md_path, "BENCH", t)
print("\n".join(t))
