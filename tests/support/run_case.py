#!/usr/bin/env python3
# SPDX-License-Identifier: LGPL-2.1-or-later
"""Run a shard scene (or a `shard material-test` case) and check its history.csv (standard library only).

A case is a directory holding <case>.prm, or a path <case>.prm; beside the .prm any of:
  <case>.reference   CSV ('nan' skips a cell): a 'time' column and history columns with values from a closed form
                     or published data (never shard's own output); history.csv is interpolated
                     linearly at each reference time.
  <case>.tolerances  CSV: column,abs,rel  -- a value passes when |x - r| <= abs + rel * |r|.
  <case>.checks      JSON list of derived checks on the history:
                       {"name", "type", "column", ..., "expected", "rel" | "abs", "source"}
                     types: mean (from, to), change (from, to), first_crossing (level),
                            last_crossing (level),
                            max_abs (optional from), final, max, min, growth (from, to),
                            relative_drift (max |y - y(0)| / |y(0)|); optional "scale" multiplies the value.
  (.checks types: mean, change (y(to) - y(from), interpolated), first_crossing, last_crossing,
   max_abs, max, min, final, relative_drift, max_filtered (largest centred moving average over
   "window" s), duration (first to last row above "level"), growth)
  <case>.summary     JSON list of checks on summary.json: {"key", "expected", "rel" | "abs"};
                     a key "a/b" looks into object a (run: "results/x"; material-test:
                     "final_state/effective plastic strain"); "expected_key" instead of
                     "expected" compares with another key of the same summary.json; "sum_of": [keys]
                     instead of "key" checks the sum of several keys (a mass balance); a last
                     part "sum" or "max" of a key reduces a list (a per-rank list: the total or
                     the largest rank); "at_most" (a number) or "at_most_key" (another key, times
                     "factor", default 1) instead of "expected" checks an upper bound.
                     --summary FILE adds the checks of FILE (a variant).
  <case>.fragments   JSON list of checks on fragment_statistics.csv, each
                       {"name", "value", "expected", "where", "aggregate", "rel" | "abs", "source"}:
                     "value" and "expected" are Python expressions of a row's columns (numbers; `body`
                     is text), the math functions and `summary` (summary.json); "where" (default
                     all rows) selects rows; "aggregate" is each (default: every selected row, at
                     least one), sum (of value over the selected rows) or count (selected rows).

Options: --command NAME is the shard command (default `run`; `material-test` for a material point
case, whose history.csv has the same 'time' column and is checked the same way); --output-key PATH
is the key that sets the output directory (default `K - Output/directory`; for material-test
`M - Material test/output directory`). The progress lines are switched off only for `run`.
--np N runs with mpiexec; --compare-ranks A B runs at both counts and requires the
histories (and fragments.csv, when written) to agree to --rel (default 1e-8) relative to max(|a|, |b|, scale), where the scale of
an energy column is the largest energy term of the run, of a momentum component the largest
component, of the energy error 1, and of any other column its largest magnitude; the coarse space
of every consistent-correction solve (functions, aggregates) must be the same at both counts.
--compare-threads A B ... runs at --np ranks with `--threads A`, `--threads B`, ... and requires
history.csv (and fragments.csv, when written) byte for byte equal to those of the first count, and
summary.json to report the thread count.
--expect-exit K and --expect-message REGEX check a run that must fail; when such a run wrote a
history (an unstable run keeps its output), its .checks, .summary and --expect-file are checked too.
--checks FILE adds the checks of FILE to those of <case>.checks (a variant of a scene run with --set);
with --instead-of-checks only the --checks files apply.
--expect-file NAME checks
that the run wrote NAME into its output directory (and turns the fragment plots on).
A failure prints case, column or check, row and both values, and exits 1.
"""
import argparse
import csv
import json
import math
import os
import re
import shlex
import shutil
import subprocess
import sys
import tempfile


def read_csv(path):
    with open(path) as f:
        rows = list(csv.reader(f))
    header = [h.strip() for h in rows[0]]
    data = [[float(x) for x in r] for r in rows[1:] if r]
    return header, data


def column(header, data, name):
    if name not in header:
        raise SystemExit(f"column '{name}' not in history (has {', '.join(header)})")
    i = header.index(name)
    return [r[i] for r in data]


def interpolate(ts, ys, t):
    if t <= ts[0]:
        return ys[0]
    for k in range(1, len(ts)):
        if ts[k] >= t:
            w = (t - ts[k - 1]) / (ts[k] - ts[k - 1]) if ts[k] > ts[k - 1] else 1.0
            return ys[k - 1] + w * (ys[k] - ys[k - 1])
    return ys[-1]


def crossing(ts, ys, level, first=True):
    """Time where ys crosses level (linear interpolation); first or last crossing."""
    found = None
    for k in range(1, len(ts)):
        a, b = ys[k - 1] - level, ys[k] - level
        if a == 0 or a * b < 0:
            t = ts[k - 1] + (ts[k] - ts[k - 1]) * (a / (a - b) if a != b else 0.0)
            if first:
                return t
            found = t
    return found


def run_shard(args, np, outdir, extra_sets=(), threads=None):
    cmd = []
    if np > 0:
        cmd = [args.mpiexec] + args.mpiexec_flags.split() + ["-np", str(np)]
    cmd += [args.shard, args.command, case_base(args) + ".prm", "--set", f"{args.output_key}={outdir}"]
    if args.command == "run":
        cmd += ["--set", "K - Output/progress interval=0"]
        # Plots cost a python start each; only cases that check one ask for them.
        if not args.expect_file:
            cmd += ["--set", "K - Output/fragment plots=false"]
    for s in list(args.set or []) + list(extra_sets):
        cmd += ["--set", s]
    if threads is None:
        threads = args.threads_argument
    if threads is not None:
        cmd += ["--threads", str(threads)]
    env = dict(os.environ, OMPI_ALLOW_RUN_AS_ROOT="1", OMPI_ALLOW_RUN_AS_ROOT_CONFIRM="1",
               DEAL_II_NUM_THREADS="1")
    p = subprocess.run(cmd, capture_output=True, text=True, env=env)
    return p, cmd


def check_value(failures, case, what, value, expected, tol_abs, tol_rel, row=None):
    ok = math.isfinite(value) and abs(value - expected) <= tol_abs + tol_rel * abs(expected)
    where = f" row {row}" if row is not None else ""
    line = (f"{case}: {what}{where}: got {value:.8g}, expected {expected:.8g} "
            f"(abs {tol_abs:g} + rel {tol_rel:g})")
    print(("ok    " if ok else "FAIL  ") + line)
    if not ok:
        failures.append(line)


def case_base(args):
    """Path of the case files without extension: --case DIR/<DIR name> or --case FILE.prm."""
    if args.case.endswith(".prm"):
        return args.case[:-4]
    return os.path.join(args.case, os.path.basename(os.path.normpath(args.case)))


def check_files(args, outdir, case, failures):
    """--expect-file: each NAME must have been written (non-empty) into the output directory."""
    for name in args.expect_file or []:
        path = os.path.join(outdir, name)
        ok = os.path.isfile(path) and os.path.getsize(path) > 0
        print(("ok    " if ok else "FAIL  ") + f"{case}: wrote {name}")
        if not ok:
            failures.append(f"{case}: {name} was not written")
    for name in args.expect_no_file or []:
        ok = not os.path.exists(os.path.join(outdir, name))
        print(("ok    " if ok else "FAIL  ") + f"{case}: did not write {name}")
        if not ok:
            failures.append(f"{case}: {name} was written")


def post_checks(args, outdir, case, failures):
    """--post-check: run each command with the output directory as its first argument."""
    # contrib/setup.sh installs numpy and h5py as Debian packages, i.e. for Debian's Python.
    python = "/usr/bin/python3" if os.path.exists("/usr/bin/python3") else sys.executable
    for command in args.post_check or []:
        words = shlex.split(command)
        p = subprocess.run([python, words[0], outdir] + words[1:], capture_output=True, text=True)
        print(p.stdout.strip())
        if p.returncode != 0:
            print(p.stderr.strip())
            failures.append(f"{case}: {os.path.basename(words[0])} failed ({p.returncode})")


def check_case(args, outdir, failures):
    base = case_base(args)
    case = os.path.basename(base)
    header, data = read_csv(os.path.join(outdir, "history.csv"))
    ts = column(header, data, "time")
    if os.path.exists(base + ".reference"):
        tol = {}
        with open(base + ".tolerances") as f:
            for r in csv.DictReader(f):
                tol[r["column"].strip()] = (float(r["abs"]), float(r["rel"]))
        rh, rd = read_csv(base + ".reference")
        for k, row in enumerate(rd):
            t = row[rh.index("time")]
            for name, expected in zip(rh, row):
                if name == "time" or math.isnan(expected):
                    continue
                a, r = tol[name]
                value = interpolate(ts, column(header, data, name), t)
                check_value(failures, case, f"{name} at t={t:g}", value, expected, a, r, k + 1)
    # The case's own checks, then those of --checks.
    own = [] if args.instead_of_checks else ([base + ".checks"] if os.path.exists(base + ".checks") else [])
    paths = own + (args.checks or [])
    checks = []
    for path in paths:
        with open(path) as f:
            checks += json.load(f)
    for c in checks:
        ys = [y * c.get("scale", 1.0) for y in column(header, data, c["column"])]
        kind = c["type"]
        if kind == "mean":
            sel = [y for t, y in zip(ts, ys) if c["from"] <= t <= c["to"]]
            value = sum(sel) / len(sel)
        elif kind in ("first_crossing", "last_crossing"):
            value = crossing(ts, ys, c["level"], kind == "first_crossing")
            value = float("nan") if value is None else value
        elif kind == "max_abs":
            value = max(abs(y) for t, y in zip(ts, ys) if t >= c.get("from", ts[0]))
        elif kind == "max":
            value = max(ys)
        elif kind == "min":
            value = min(ys)
        elif kind == "final":
            value = ys[-1]
        elif kind == "relative_drift":
            # Largest |y - y(0)| / |y(0)| over the run (conserved quantities).
            value = max(abs(y - ys[0]) for y in ys) / abs(ys[0])
        elif kind == "max_filtered":
            # Largest moving average over a centred time window (e.g. a contact force without
            # the ringing of the discrete wave front); "window" in s.
            w = 0.5 * c["window"]
            value = max(sum(yy for tt, yy in zip(ts, ys) if t - w <= tt <= t + w) /
                        max(1, sum(1 for tt in ts if t - w <= tt <= t + w))
                        for t in ts if ts[0] + w <= t <= ts[-1] - w)
        elif kind == "duration":
            # Time from the first to the last row where the column exceeds "level".
            on = [t for t, y in zip(ts, ys) if y > c["level"]]
            value = on[-1] - on[0] if on else 0.0
        elif kind == "change":
            # y(to) - y(from), both interpolated linearly between the history rows.
            value = interpolate(ts, ys, c["to"]) - interpolate(ts, ys, c["from"])
        elif kind == "growth":
            # Largest |y| after "from" over the largest |y| up to "to" (no growth: <= 1).
            late = max(abs(y) for t, y in zip(ts, ys) if t >= c["from"])
            early = max(abs(y) for t, y in zip(ts, ys) if t <= c["to"])
            value = late / early
        elif kind == "impulse_balance":
            # Momentum balance: largest |y(t) - y(0) - integral of the force columns dt| over
            # the rows (trapezoidal rule on the history rows), e.g. the momentum of a body
            # against the applied load and the support reactions.
            fs = [sum(r) for r in zip(*[column(header, data, n) for n in c["forces"]])]
            impulse, value = 0.0, 0.0
            for k in range(1, len(ts)):
                impulse += 0.5 * (ts[k] - ts[k - 1]) * (fs[k] + fs[k - 1]) * c.get("scale", 1.0)
                if ts[k] >= c.get("from", ts[0]):
                    value = max(value, abs(ys[k] - ys[0] - impulse))
        else:
            raise SystemExit(f"unknown check type {kind}")
        check_value(failures, case, f"{c['name']} ({c.get('source', '')})", value, c["expected"],
                    c.get("abs", 0.0), c.get("rel", 0.0))
    summary_checks = []
    for path in ([base + ".summary"] if os.path.exists(base + ".summary") else []) + (args.summary or []):
        with open(path) as f:
            summary_checks += json.load(f)
    if summary_checks:
        with open(os.path.join(outdir, "summary.json")) as f:
            summary = json.load(f)
        for c in summary_checks:
            def lookup(key):
                v = summary
                for part in key.split("/"):
                    if isinstance(v, list) and part in ("sum", "max"):
                        v = sum(v) if part == "sum" else max(v)
                    else:
                        v = v[part]
                return v
            if "sum_of" in c:
                c = dict(c, key=" + ".join(c["sum_of"]))
                v = sum(float(lookup(k)) for k in c["sum_of"])
            else:
                v = lookup(c["key"])
            if "at_most" in c or "at_most_key" in c:
                bound = (float(c["at_most"]) if "at_most" in c
                         else c.get("factor", 1.0) * float(lookup(c["at_most_key"])))
                ok = float(v) <= bound
                what = f"at most {bound:.8g}" + (f" ({c.get('factor', 1.0):g} x {c['at_most_key']})"
                                                 if "at_most_key" in c else "")
                print(("ok    " if ok else "FAIL  ") + f"{case}: summary {c['key']}: got {float(v):.8g}, {what}"
                      + (f" ({c['source']})" if "source" in c else ""))
                if not ok:
                    failures.append(f"{case}: summary {c['key']} = {v}, expected {what}")
                continue
            if "expected_key" in c:
                # Two results of one run that a conservation law makes equal (e.g. the
                # fragment masses and the nodal mass).
                e = lookup(c["expected_key"])
                c = dict(c, expected=float(e), key=f"{c['key']} (against {c['expected_key']})")
            if isinstance(c["expected"], str):
                ok = v == c["expected"]
                print(("ok    " if ok else "FAIL  ") + f"{case}: summary {c['key']} = {v}")
                if not ok:
                    failures.append(f"{case}: summary {c['key']} = {v}, expected {c['expected']}")
            else:
                check_value(failures, case, f"summary {c['key']}", float(v), c["expected"],
                            c.get("abs", 0.0), c.get("rel", 0.0))
    if os.path.exists(base + ".fragments"):
        check_fragments(base + ".fragments", outdir, case, failures)


def check_fragments(path, outdir, case, failures):
    """The checks of PATH (<case>.fragments) on fragment_statistics.csv (see the module doc)."""
    with open(os.path.join(outdir, "fragment_statistics.csv")) as f:
        rows = [{k: (v if k == "body" else float(v)) for k, v in r.items()} for r in csv.DictReader(f)]
    summary_path = os.path.join(outdir, "summary.json")
    summary = json.load(open(summary_path)) if os.path.exists(summary_path) else {}
    names = {k: getattr(math, k) for k in dir(math) if not k.startswith("_")}

    def evaluate(expression, row):
        if not isinstance(expression, str):
            return float(expression)
        return float(eval(expression, {"__builtins__": {}}, {**names, "summary": summary, **row}))

    with open(path) as f:
        checks = json.load(f)
    for c in checks:
        selected = [r for r in rows if evaluate(c.get("where", "1"), r)]
        label = f"{c['name']} ({c.get('source', '')})"
        kind = c.get("aggregate", "each")
        tol_abs, tol_rel = c.get("abs", 0.0), c.get("rel", 0.0)
        if kind == "each":
            if not selected:
                print(f"FAIL  {case}: fragments {label}: no row where {c.get('where')}")
                failures.append(f"{case}: fragments {c['name']}: no row selected")
                continue
            bad = None
            for r in selected:
                value, expected = evaluate(c["value"], r), evaluate(c["expected"], r)
                if not abs(value - expected) <= tol_abs + tol_rel * abs(expected):
                    bad = (r, value, expected)
                    break
            if bad:
                r, value, expected = bad
                check_value(failures, case, f"fragments {label}, fragment {int(r['fragment'])}", value, expected,
                            tol_abs, tol_rel)
            else:
                print(f"ok    {case}: fragments {label}: {len(selected)} rows")
        else:
            value = sum(evaluate(c["value"], r) for r in selected) if kind == "sum" else float(len(selected))
            check_value(failures, case, f"fragments {label} ({kind} over {len(selected)} rows)", value,
                        evaluate(c["expected"], {}), tol_abs, tol_rel)


def compare_histories(a, b, rel, failures, case):
    ha, da = read_csv(os.path.join(a, "history.csv"))
    hb, db = read_csv(os.path.join(b, "history.csv"))
    if ha != hb or len(da) != len(db):
        failures.append(f"{case}: histories differ in shape ({len(da)} vs {len(db)} rows)")
        return
    # Columns of one kind share a scale: an energy term is compared with the largest energy of
    # the run, a momentum component with the largest component; the energy error is already
    # relative (scale 1). Other columns use their own largest magnitude.
    groups = {"energy": ["kinetic_energy", "internal_energy", "hourglass_energy", "external_work",
                         "boundary_work"],
              "momentum": ["momentum_x", "momentum_y", "momentum_z"]}

    def magnitude(names):
        idx = [ha.index(n) for n in names if n in ha]
        return max([abs(r[j]) for r in da + db for j in idx] + [0.0])

    worst = (0.0, None)
    for j, name in enumerate(ha):
        group = [g for g in groups.values() if name in g]
        scale = 1.0 if name == "energy_error" else magnitude(group[0] if group else [name])
        for k, (ra, rb) in enumerate(zip(da, db)):
            x, y = ra[j], rb[j]
            d = abs(x - y) / max(abs(x), abs(y), scale, 1e-300)
            if d > worst[0]:
                worst = (d, (name, k + 1, x, y))
            if not d <= rel:
                failures.append(f"{case}: column {name} row {k + 1}: {x!r} vs {y!r} (relative {d:.3g} > {rel:g})")
                return
    print(f"ok    {case}: histories agree, largest relative difference {worst[0]:.3g}"
          + (f" ({worst[1][0]} row {worst[1][1]})" if worst[1] else ""))


def compare_fragments(a, b, rel, failures, case):
    """fragments.csv (when the run writes one) must agree too: same fragments, same rows,
    each column to rel of its largest magnitude."""
    fa, fb = os.path.join(a, "fragments.csv"), os.path.join(b, "fragments.csv")
    if not os.path.exists(fa) and not os.path.exists(fb):
        return
    if not (os.path.exists(fa) and os.path.exists(fb)):
        failures.append(f"{case}: fragments.csv written at one rank count only")
        return
    ha, da = read_csv(fa)
    hb, db = read_csv(fb)
    if ha != hb or len(da) != len(db):
        failures.append(f"{case}: fragments.csv differ in shape ({len(da)} vs {len(db)} rows)")
        return
    # Coordinates share one scale, as do velocity components (a centre on a symmetry plane is
    # round-off around 0).
    groups = [["x", "y", "z"], ["vx", "vy", "vz"]]
    worst = 0.0
    for j, name in enumerate(ha):
        group = next((g for g in groups if name in g), [name])
        idx = [ha.index(n) for n in group if n in ha]
        scale = max([abs(r[i]) for r in da + db for i in idx] + [1e-300])
        for k, (ra, rb) in enumerate(zip(da, db)):
            d = abs(ra[j] - rb[j]) / scale
            worst = max(worst, d)
            if d > rel:
                failures.append(f"{case}: fragments.csv column {name} row {k + 1}: {ra[j]!r} vs {rb[j]!r}")
                return
    print(f"ok    {case}: fragments agree ({len(da)} rows), largest relative difference {worst:.3g}")


def compare_threads(args, tmp, failures, case):
    """Runs at each count of --compare-threads; the files of the first count are the reference."""
    dirs = []
    for n in args.compare_threads:
        out = os.path.join(tmp, f"threads{n}")
        p, cmd = run_shard(args, args.np, out, threads=n)
        if p.returncode != 0:
            print(p.stdout, p.stderr)
            raise SystemExit(f"{case}: run at {n} threads failed ({p.returncode}): {' '.join(cmd)}")
        with open(os.path.join(out, "summary.json")) as f:
            reported = json.load(f).get("n_threads")
        if reported != n:
            failures.append(f"{case}: summary.json reports n_threads = {reported}, expected {n}")
        dirs.append(out)
    ref = dirs[0]
    for n, out in zip(args.compare_threads[1:], dirs[1:]):
        for name in ("history.csv", "fragments.csv"):
            a, b = os.path.join(ref, name), os.path.join(out, name)
            if not os.path.exists(a) and not os.path.exists(b):
                continue
            if not (os.path.exists(a) and os.path.exists(b)):
                failures.append(f"{case}: {name} written at only one of {args.compare_threads[0]} and {n} threads")
                continue
            with open(a) as f:
                la = f.read().splitlines()
            with open(b) as f:
                lb = f.read().splitlines()
            if la == lb:
                print(f"ok    {case}: {name} identical at {args.compare_threads[0]} and {n} threads "
                      f"({len(la) - 1} rows)")
                continue
            row = next((k for k, (x, y) in enumerate(zip(la, lb)) if x != y), min(len(la), len(lb)))
            failures.append(f"{case}: {name} differs between {args.compare_threads[0]} and {n} threads "
                            f"from line {row + 1}:\n  {la[row] if row < len(la) else '<end>'}\n  "
                            f"{lb[row] if row < len(lb) else '<end>'}")


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--shard", required=True)
    ap.add_argument("--case", required=True)
    ap.add_argument("--command", default="run", help="shard command: run (default) or material-test")
    ap.add_argument("--output-key", default="K - Output/directory",
                    help="key of the output directory (material-test: 'M - Material test/output directory')")
    ap.add_argument("--np", type=int, default=0)
    ap.add_argument("--mpiexec", default="mpiexec")
    ap.add_argument("--mpiexec-flags", default="--allow-run-as-root --oversubscribe")
    ap.add_argument("--compare-ranks", type=int, nargs=2)
    ap.add_argument("--compare-threads", type=int, nargs="+",
                    help="run at each thread count (at --np ranks) and require history.csv and "
                         "fragments.csv byte for byte equal to those of the first count")
    ap.add_argument("--threads-argument", help="passed as `--threads VALUE` to the run (for the tests of bad values)")
    ap.add_argument("--rel", type=float, default=1e-8)
    ap.add_argument("--set", action="append")
    ap.add_argument("--checks", action="append",
                    help="a further .checks file, applied after the case's own (a variant of a scene run with --set)")
    ap.add_argument("--summary", action="append",
                    help="a further .summary file of checks on summary.json, applied after the case's own")
    ap.add_argument("--instead-of-checks", action="store_true",
                    help="apply only the --checks files, not the case's own .checks (a variant whose "
                         "expectations differ, e.g. another impact speed)")
    ap.add_argument("--expect-exit", type=int)
    ap.add_argument("--expect-message")
    ap.add_argument("--expect-file", action="append",
                    help="a file the run must write into its output directory (e.g. fragments.png)")
    ap.add_argument("--expect-no-file", action="append",
                    help="a file the run must not write into its output directory")
    ap.add_argument("--post-check", action="append",
                    help="a command (a Python script and its arguments) run after a successful run with the "
                         "output directory as its first argument; a non-zero exit is a failure")
    ap.add_argument("--keep", action="store_true")
    args = ap.parse_args()
    case = os.path.basename(case_base(args))
    tmp = tempfile.mkdtemp(prefix=f"shard-{case}-")
    failures = []
    try:
        if args.compare_threads:
            compare_threads(args, tmp, failures, case)
        elif args.compare_ranks:
            dirs, logs = [], []
            for n in args.compare_ranks:
                out = os.path.join(tmp, f"np{n}")
                p, cmd = run_shard(args, n, out)
                if p.returncode != 0:
                    print(p.stdout, p.stderr)
                    raise SystemExit(f"{case}: run at {n} ranks failed ({p.returncode}): {' '.join(cmd)}")
                dirs.append(out)
                logs.append(p.stderr)
            compare_histories(dirs[0], dirs[1], args.rel, failures, case)
            compare_fragments(dirs[0], dirs[1], args.rel, failures, case)
            # The coarse space of every consistent-correction solve (rank 0 reports it on stderr) is
            # the same at any rank count (decision 0009, amended 2026-12-07).
            spaces = [re.findall(r"coarse space (\d+) functions on (\d+) aggregates", text) for text in logs]
            print(("ok    " if spaces[0] == spaces[1] else "FAIL  ") +
                  f"{case}: coarse spaces of {len(spaces[0])} correction solves equal at both rank counts")
            if spaces[0] != spaces[1]:
                failures.append(f"{case}: coarse spaces of the correction solves differ: "
                                f"{args.compare_ranks[0]} ranks {spaces[0][:4]}..., {args.compare_ranks[1]} ranks {spaces[1][:4]}...")
        else:
            out = os.path.join(tmp, "out")
            p, cmd = run_shard(args, args.np, out)
            if args.expect_exit is not None:
                text = p.stdout + p.stderr
                print(text.strip())
                if p.returncode != args.expect_exit:
                    failures.append(f"{case}: exit code {p.returncode}, expected {args.expect_exit}")
                if args.expect_message and not re.search(args.expect_message, text):
                    failures.append(f"{case}: message does not match /{args.expect_message}/")
                # A run stopped as unstable keeps the output written so far: its history and
                # summary are checked like a completed run's (.checks, .summary, --expect-file).
                if os.path.exists(os.path.join(out, "history.csv")):
                    check_case(args, out, failures)
                check_files(args, out, case, failures)
            else:
                if p.returncode != 0:
                    print(p.stdout, p.stderr)
                    raise SystemExit(f"{case}: run failed ({p.returncode}): {' '.join(cmd)}")
                check_case(args, out, failures)
                check_files(args, out, case, failures)
                post_checks(args, out, case, failures)
    finally:
        if args.keep:
            print("kept", tmp)
        else:
            shutil.rmtree(tmp, ignore_errors=True)
    if failures:
        print("\n".join("FAILED: " + f for f in failures))
        sys.exit(1)
    print(f"{case}: all checks passed")


if __name__ == "__main__":
    main()
