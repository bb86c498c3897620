#!/usr/bin/env python3
# SPDX-License-Identifier: LGPL-2.1-or-later
"""Bit-for-bit comparison of two shard binaries on every regression scene.

A refactoring must not change results (issue 27: "every history.csv of the regression scenes is
identical to before, bit for bit, at 1 and 2 ranks and with threads"). This script lists the
scene tests of the build directory (`ctest -N -V`, the tests that call tests/support/run_case.py,
without the labels verification and benchmark unless --labels says otherwise), runs each one
twice, once with the reference binary and once with the new one (`--keep`), and compares every
history.csv and fragments.csv of the two runs byte for byte (files under the kept directories,
matched by relative path; a run at 1 and 2 ranks or with threads writes several).

The checks of run_case.py run as in ctest; their verdict is reported but a failing check is
not a difference. Typical use, with a build of the commit before the change kept aside:

    git stash; cmake --build build --target shard; cp build/bin/shard /tmp/shard_ref; git stash pop
    cmake --build build --target shard
    contrib/utilities/same_history.py --reference /tmp/shard_ref -j 2

Exit code 0 when every compared file is identical and both binaries wrote the same file set.
"""
import argparse
import concurrent.futures
import filecmp
import os
import re
import shlex
import shutil
import subprocess
import sys

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
COMPARED = ("history.csv", "fragments.csv")


def scene_tests(build, exclude, include):
    """(name, argv) of the run_case.py tests of the build directory."""
    cmd = ["ctest", "-N", "-V"]
    if exclude:
        cmd += ["-LE", exclude]
    if include:
        cmd += ["-R", include]
    text = subprocess.run(cmd, cwd=build, capture_output=True, text=True, check=True).stdout
    tests, command = [], None
    for line in text.splitlines():
        m = re.match(r"\s*\d+: Test command: (.*)$", line)
        if m:
            command = shlex.split(m.group(1))
            continue
        m = re.match(r"\s*Test\s+#\d+: (\S+)", line)
        if m and command is not None:
            if any(a.endswith("run_case.py") for a in command):
                tests.append((m.group(1), command))
            command = None
    return tests


def with_binary(argv, binary):
    out = list(argv)
    i = out.index("--shard")
    out[i + 1] = binary
    return out + ["--keep"]


def run(argv):
    p = subprocess.run(argv, capture_output=True, text=True)
    kept = re.findall(r"^kept (\S+)$", p.stdout, re.M)
    return p.returncode, (kept[-1] if kept else None), p.stdout[-2000:] + p.stderr[-2000:]


def tables(directory):
    found = {}
    for base, _, files in os.walk(directory):
        for f in files:
            if f in COMPARED:
                path = os.path.join(base, f)
                found[os.path.relpath(path, directory)] = path
    return found


def compare(name, argv, reference, new):
    rc_ref, dir_ref, log_ref = run(with_binary(argv, reference))
    rc_new, dir_new, log_new = run(with_binary(argv, new))
    lines, ok = [], True
    if rc_ref != rc_new:
        lines.append(f"  exit code {rc_ref} (reference) vs {rc_new} (new)")
        ok = False
    if dir_ref is None or dir_new is None:
        lines.append("  no kept directory (run_case.py stopped early):\n" + (log_new if dir_new is None else log_ref))
        return name, False, 0, lines
    a, b = tables(dir_ref), tables(dir_new)
    if set(a) != set(b):
        lines.append(f"  different files: reference {sorted(a)}, new {sorted(b)}")
        ok = False
    n = 0
    for rel in sorted(set(a) & set(b)):
        n += 1
        if not filecmp.cmp(a[rel], b[rel], shallow=False):
            ok = False
            ra, rb = open(a[rel]).read().splitlines(), open(b[rel]).read().splitlines()
            first = next((k for k in range(min(len(ra), len(rb))) if ra[k] != rb[k]), min(len(ra), len(rb)))
            lines.append(f"  {rel} differs (lines {len(ra)} vs {len(rb)}), first at line {first + 1}")
            if first < min(len(ra), len(rb)):
                lines.append(f"    ref: {ra[first][:200]}\n    new: {rb[first][:200]}")
    if rc_new != 0:
        lines.append(f"  note: run_case.py exit {rc_new} with the new binary (checks): {log_new[-400:]}")
    shutil.rmtree(dir_ref, ignore_errors=True)
    shutil.rmtree(dir_new, ignore_errors=True)
    return name, ok, n, lines


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--reference", required=True, help="the shard binary of the commit before the change")
    ap.add_argument("--new", default=os.path.join(ROOT, "build", "bin", "shard"))
    ap.add_argument("--build", default=os.path.join(ROOT, "build"))
    ap.add_argument("--labels-exclude", default="verification|benchmark")
    ap.add_argument("-R", "--regex", help="only tests whose name matches (ctest -R)")
    ap.add_argument("-j", type=int, default=1, help="tests run at once (each runs both binaries in turn)")
    args = ap.parse_args()
    tests = scene_tests(args.build, args.labels_exclude, args.regex)
    if not tests:
        sys.exit("same_history.py: no scene tests found in " + args.build)
    print(f"same_history.py: {len(tests)} scene tests, reference {args.reference}, new {args.new}", flush=True)
    bad, files = [], 0
    with concurrent.futures.ThreadPoolExecutor(max_workers=args.j) as pool:
        futures = [pool.submit(compare, n, a, os.path.abspath(args.reference), os.path.abspath(args.new))
                   for n, a in tests]
        for f in concurrent.futures.as_completed(futures):
            name, ok, n, lines = f.result()
            files += n
            print(f"{'same' if ok else 'DIFF'}  {name} ({n} tables)", flush=True)
            for line in lines:
                print(line, flush=True)
            if not ok:
                bad.append(name)
    print(f"same_history.py: {len(tests) - len(bad)} of {len(tests)} tests identical ({files} tables compared)")
    if bad:
        print("different: " + " ".join(sorted(bad)))
        sys.exit(1)


if __name__ == "__main__":
    main()
