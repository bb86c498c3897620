#!/usr/bin/env python3
# SPDX-License-Identifier: LGPL-2.1-or-later
"""Checkpoint and restart tests of a shard scene (standard library only; doc/manual/checkpoint.md).

Modes:
  --mode equal   Runs the scene straight at --np-restart ranks (the reference). Runs it again at
                 --np-write ranks with a checkpoint every --interval steps, stopped by
                 `max steps` --stop-after steps later than the first checkpoint, then restarts
                 from the checkpoint directory at --np-restart ranks to the end. With --rel 0
                 (same rank count) history.csv, fragments.csv and the results of summary.json
                 must be byte- and bit-identical to the reference; otherwise they must agree to
                 --rel (run_case.py's scaled relative difference) and the largest difference is
                 printed.
  --mode kill    Like equal at one rank, but the checkpointed run is killed with SIGKILL while it
                 writes its second checkpoint (the test hook SHARD_CHECKPOINT_TEST_PAUSE=<step>
                 stops the write half way). The checkpoint directory must then hold the first
                 checkpoint complete and the second one without manifest; the restart from the
                 directory must take the first and end bit-identical to the reference.
  --mode reject  Writes one checkpoint, then checks that a restart is refused before the run, with
                 exit code 1 and a message naming the key and the file: from a rank file with one
                 byte changed ("is corrupt"), from a checkpoint of another scene (a --set of
                 --other-scene changes a parameter: "another scene") and from a directory that
                 holds only an incomplete checkpoint ("no complete checkpoint").
Every failure prints what differs and exits 1.
"""
import argparse
import json
import os
import shutil
import signal
import subprocess
import sys
import tempfile
import time

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import run_case  # noqa: E402


def command(args, np, outdir, sets):
    cmd = []
    if np > 0:
        cmd = [args.mpiexec] + args.mpiexec_flags.split() + ["-np", str(np)]
    cmd += [args.shard, "run", args.case, "--set", f"K - Output/directory={outdir}",
            "--set", "K - Output/progress interval=0", "--set", "K - Output/fragment plots=false"]
    for s in list(args.set or []) + list(sets):
        cmd += ["--set", s]
    return cmd


def environment(extra=None):
    env = dict(os.environ, OMPI_ALLOW_RUN_AS_ROOT="1", OMPI_ALLOW_RUN_AS_ROOT_CONFIRM="1",
               DEAL_II_NUM_THREADS="1")
    env.update(extra or {})
    return env


def run(args, np, outdir, sets, failures, what):
    cmd = command(args, np, outdir, sets)
    p = subprocess.run(cmd, capture_output=True, text=True, env=environment())
    if p.returncode != 0:
        failures.append(f"{what}: exit {p.returncode}\n  {' '.join(cmd)}\n{p.stderr[-3000:]}")
    return p


def summary_values(path):
    with open(path) as f:
        s = json.load(f)
    keep = ["status", "steps", "final_time", "last_dt", "n_particles", "n_converted_elements",
            "conversion_events", "conversion_energy", "broken_bonds", "free_particles", "n_fragments",
            "fragment_mass_total", "largest_fragment_mass", "energy_error", "max_abs_energy_error"]
    out = {k: s[k] for k in keep if k in s}
    out.update({"results/" + k: v for k, v in s.get("results", {}).items()})
    return out


def compare(args, ref, out, rel, failures):
    case = os.path.basename(args.case)
    if rel == 0:
        for name in ["history.csv", "fragments.csv"]:
            a, b = os.path.join(ref, name), os.path.join(out, name)
            if os.path.exists(a) != os.path.exists(b):
                failures.append(f"{case}: {name} written by only one of the runs")
            elif os.path.exists(a):
                with open(a, "rb") as fa, open(b, "rb") as fb:
                    da, db = fa.read(), fb.read()
                if da != db:
                    la, lb = da.decode().splitlines(), db.decode().splitlines()
                    row = next((k for k, (x, y) in enumerate(zip(la, lb)) if x != y), min(len(la), len(lb)))
                    failures.append(f"{case}: {name} differs from row {row} ({len(la)} vs {len(lb)} rows):\n"
                                    f"  straight:  {la[row][:200] if row < len(la) else '(end)'}\n"
                                    f"  restarted: {lb[row][:200] if row < len(lb) else '(end)'}")
                else:
                    print(f"ok    {case}: {name} byte-identical ({len(da.splitlines())} rows)")
    else:
        run_case.compare_histories(ref, out, rel, failures, case)
    sa, sb = summary_values(os.path.join(ref, "summary.json")), summary_values(os.path.join(out, "summary.json"))
    worst = (0.0, "")
    for k in sorted(set(sa) | set(sb)):
        x, y = sa.get(k), sb.get(k)
        if isinstance(x, (int, float)) and isinstance(y, (int, float)) and not isinstance(x, bool):
            d = abs(x - y) / max(abs(x), abs(y), 1e-300) if x != y else 0.0
            if d > worst[0]:
                worst = (d, k)
            if (rel == 0 and x != y) or d > args.summary_rel:
                failures.append(f"{case}: summary.json {k}: straight {x!r}, restarted {y!r}")
        elif x != y:
            failures.append(f"{case}: summary.json {k}: straight {x!r}, restarted {y!r}")
    print(f"{'ok   ' if not failures else 'FAIL '} {case}: summary.json compared ({len(sa)} values), largest "
          f"relative difference {worst[0]:.3g} {worst[1]}")


def reject(args, out, ckpt, failures):
    run(args, args.np_write, out, [f"N - Checkpoint/interval={args.interval}",
                                   f"J - Time integration/max steps={args.interval}"], failures, "checkpointed run")
    if failures:
        return
    name = f"checkpoint_{args.interval:08d}"
    key = "N - Checkpoint/restart from"

    def expect(what, sets, pattern):
        cmd = command(args, 0, out + "-" + what.replace(" ", "_"), sets)
        p = subprocess.run(cmd, capture_output=True, text=True, env=environment())
        if p.returncode != 1 or key not in p.stderr or pattern not in p.stderr:
            failures.append(f"{what}: expected exit 1 and '{key} ... {pattern}', got exit {p.returncode}:\n"
                            + p.stderr[-1500:])
        else:
            print(f"ok    {what}: {[l for l in p.stderr.splitlines() if key in l][0][:300]}")

    expect("other scene", [f"{key}={ckpt}", args.other_scene], "another scene")
    # One byte changed in the middle of the rank file.
    bad = os.path.join(os.path.dirname(ckpt), "corrupt")
    shutil.copytree(ckpt, bad)
    rank_file = os.path.join(bad, name + ".rank0.bin")
    with open(rank_file, "r+b") as f:
        f.seek(os.path.getsize(rank_file) // 2)
        b = f.read(1)
        f.seek(-1, 1)
        f.write(bytes([b[0] ^ 0xFF]))
    expect("corrupt file", [f"{key}={bad}"], "is corrupt")
    # A checkpoint without its manifest (a write that never finished).
    incomplete = os.path.join(os.path.dirname(ckpt), "incomplete")
    os.makedirs(incomplete)
    shutil.copy(os.path.join(ckpt, name + ".rank0.bin"), incomplete)
    expect("incomplete checkpoint", [f"{key}={incomplete}"], "no complete checkpoint")


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--shard", required=True)
    ap.add_argument("--case", required=True, help="the .prm file")
    ap.add_argument("--mode", choices=["equal", "kill", "reject"], default="equal")
    ap.add_argument("--other-scene", default="J - Time integration/safety factor=0.8",
                    help="reject mode: a --set that makes another scene")
    ap.add_argument("--np-write", type=int, default=1)
    ap.add_argument("--np-restart", type=int, default=1)
    ap.add_argument("--interval", type=int, required=True, help="checkpoint interval (steps)")
    ap.add_argument("--stop-after", type=int, default=7,
                    help="the checkpointed run stops this many steps after the first checkpoint")
    ap.add_argument("--rel", type=float, default=0.0, help="0: bitwise; else the allowed relative difference")
    ap.add_argument("--summary-rel", type=float, default=1e-6,
                    help="with --rel > 0: allowed relative difference of the summary.json values")
    ap.add_argument("--mpiexec", default="mpiexec")
    ap.add_argument("--mpiexec-flags", default="--allow-run-as-root --oversubscribe")
    ap.add_argument("--set", action="append")
    ap.add_argument("--keep", action="store_true")
    args = ap.parse_args()
    args.case = os.path.abspath(args.case)
    failures = []
    tmp = tempfile.mkdtemp(prefix="shard-restart-")
    ref, out = os.path.join(tmp, "straight"), os.path.join(tmp, "restarted")
    ckpt = os.path.join(out, "checkpoint")
    try:
        if args.mode == "reject":
            reject(args, out, ckpt, failures)
            raise StopIteration
        run(args, args.np_restart, ref, [], failures, "straight run")
        if args.mode == "equal":
            run(args, args.np_write, out, [f"N - Checkpoint/interval={args.interval}",
                                           f"J - Time integration/max steps={args.interval + args.stop_after}"],
                failures, "checkpointed run")
        else:
            # Killed in the middle of the second checkpoint write.
            cmd = command(args, 0, out, [f"N - Checkpoint/interval={args.interval}"])
            env = environment({"SHARD_CHECKPOINT_TEST_PAUSE": str(2 * args.interval)})
            err = os.path.join(tmp, "killed.stderr")
            with open(err, "w") as f:
                p = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=f, env=env, start_new_session=True)
            deadline = time.time() + 300
            while time.time() < deadline and p.poll() is None:
                with open(err) as f:
                    if "test hook: paused" in f.read():
                        break
                time.sleep(0.1)
            if p.poll() is not None:
                with open(err) as f:
                    failures.append(f"the run ended (exit {p.returncode}) before the test hook paused it:\n"
                                    + f.read()[-2000:])
            else:
                os.killpg(p.pid, signal.SIGKILL)
                p.wait()
                names = sorted(os.listdir(ckpt))
                first, second = f"checkpoint_{args.interval:08d}", f"checkpoint_{2 * args.interval:08d}"
                print("      killed during the write; checkpoint directory:", " ".join(names))
                if first + ".manifest" not in names:
                    failures.append(f"no complete first checkpoint after the kill: {names}")
                if second + ".manifest" in names or second + ".rank0.bin" in names:
                    failures.append(f"the second checkpoint looks complete after the kill: {names}")
                if second + ".rank0.bin.tmp" not in names:
                    failures.append(f"the kill did not hit the write of the second checkpoint: {names}")
        if not failures:
            p = run(args, args.np_restart, out, [f"N - Checkpoint/restart from={ckpt}"], failures, "restarted run")
            line = [l for l in p.stderr.splitlines() if "restart from" in l]
            print("     ", line[0] if line else "(no restart line)")
            want = f"checkpoint_{args.interval:08d}.manifest"
            if line and want not in line[0]:
                failures.append(f"restarted from the wrong checkpoint (expected {want}): {line[0]}")
        if not failures:
            compare(args, ref, out, args.rel, failures)
    except StopIteration:
        pass
    finally:
        if args.keep:
            print("kept", tmp)
        else:
            shutil.rmtree(tmp, ignore_errors=True)
    for f in failures:
        print("FAIL ", f)
    sys.exit(1 if failures else 0)


if __name__ == "__main__":
    main()
