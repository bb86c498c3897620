#!/usr/bin/env python3
# SPDX-License-Identifier: LGPL-2.1-or-later
"""Bad input and restarts: one test per defect of the fuzzing audit of issue 32 (standard library only).

Usage: bad_input_test.py --shard build/bin/shard --defect D01 [--root .]

Each defect has a check below: it runs `shard` in a scratch directory on a scene of prm/verification/
(or on an input it writes itself: broken meshes are made from prm/verification/two_bars_loads/bar.msh)
and requires the contract of DEVELOPERS.md rule 3 (doc/manual/testing.md, "Bad input"):
  exit 1 for bad input, with one line naming the key (or file) and what is allowed;
  exit 2 for a command-line error; exit 3 for an unstable run;
  never a crash, a library dump (Stacktrace, Errc, Additional information), non-finite results with
  exit 0, invalid JSON, or an earlier run's results touched by a run that does not start.
Prints 'ok' or 'FAIL' per check and a closing line 'N passed, M failed'; exits 1 on a failure.
"""
import argparse
import json
import math
import os
import re
import shutil
import subprocess
import sys
import tempfile

ARGS = None
RESULTS = []
DUMP = re.compile(r"Stacktrace|Errc|Additional information|Message:  <|An error occurred in line")


def scene(rel):
    return os.path.join(ARGS.root, "prm", "verification", rel)


def shard(*argv, cwd, timeout=120):
    env = dict(os.environ, OMPI_ALLOW_RUN_AS_ROOT="1", OMPI_ALLOW_RUN_AS_ROOT_CONFIRM="1", DEAL_II_NUM_THREADS="1")
    cmd = [ARGS.shard] + list(argv)
    try:
        p = subprocess.run(cmd, cwd=cwd, capture_output=True, text=True, errors="replace", env=env, timeout=timeout)
    except subprocess.TimeoutExpired:
        return -999, f"timeout after {timeout} s: {cmd}"
    return p.returncode, p.stdout + p.stderr


def check(name, ok, detail=""):
    RESULTS.append(ok)
    print(("ok    " if ok else "FAIL  ") + name + ("" if ok else f"\n      {detail}"))


def expect(name, result, code, pattern=None):
    """exit code, one located message matching pattern, no library dump."""
    rc, out = result
    check(f"{name}: exit {code}", rc == code, f"exit {rc}; output:\n{out[-1500:]}")
    check(f"{name}: no library dump", not DUMP.search(out), out[-1500:])
    if pattern:
        check(f"{name}: message /{pattern}/", re.search(pattern, out) is not None, out[-1500:])


def finite_history(path):
    with open(path) as f:
        lines = f.read().splitlines()
    bad = [x for line in lines[1:] for x in line.split(",") if not math.isfinite(float(x))]
    return not bad


SHORT = ["--set", "K - Output/progress interval=0", "--set", "K - Output/fragment plots=false"]
BAR = "elastic_bar_wall/elastic_bar_wall.prm"


def d01(w):
    for form in ("/=1", "//=1", "A//b=1", "C - Materials/=1"):
        expect(f"run --set '{form}'", shard("run", scene(BAR), "--set", form, cwd=w), 2, "malformed --set")
    expect("print-parameters --set //=1", shard("print-parameters", "--set", "//=1", cwd=w), 2, "malformed --set")
    expect("material-test --set /=1",
           shard("material-test", scene("concrete/uniaxial_tension.prm"), "--set", "/=1", cwd=w), 2, "malformed --set")


def d02(w):
    expect("unknown key in a second --set",
           shard("run", scene(BAR), "--set", "J - Time integration/max steps=5", "--set",
                 "C - Materials/steel/densty=1", cwd=w), 1,
           r"--set C - Materials/steel/densty: unknown key 'densty'\. Did you mean 'density'\? "
           r"Keys of subsection 'C - Materials/steel'")
    expect("a newline in a --set value",
           shard("run", scene(BAR), "--set",
                 "J - Time integration/max steps=3\nend\nsubsection C - Materials\nsubsection steel\n"
                 "set density = 1000\nend\nend\nsubsection J - Time integration", cwd=w), 2, "line break")
    check("a newline in a --set value: nothing ran", not os.path.exists(os.path.join(w, "output")))


def d03(w):
    for expr in ("x+;0;0", "sin(;0;0", "x*;0;0"):
        expect(f"initial velocity={expr}",
               shard("run", scene(BAR), "--set", f"B - Mesh/bar/initial velocity={expr}", cwd=w), 1,
               r"--set B - Mesh/bar/initial velocity: B - Mesh/bar/initial velocity = .*: .*(Unexpected|expected|Too few)")
    expect("l2_error with a broken expression",
           shard("run", scene(BAR), "--set", "L - Quantities/quantities=q = l2_error all x+ 0 0", cwd=w), 1,
           r"L - Quantities/quantities = .*exact displacement")


def bar_msh():
    with open(scene("two_bars_loads/bar.msh")) as f:
        return f.read()


def d04(w):
    shutil.copy(scene("two_bars_loads/two_bars_loads.prm"), w)
    text = bar_msh()
    broken = {
        "garbage.msh": bytes((37 + 101 * i) % 95 + 32 for i in range(5000)),  # printable noise
        "binary.msh": bytes(range(256)) * 4,
        "empty.msh": b"",
        "v4_header.msh": text.replace("2.2 0 8", "4.1 0 8", 1).encode(),
        "truncated.msh": text[: len(text) // 2].encode(),
        "missing_node.msh": text.replace("\n608 5 2 1 1 254 255 306 305 407 408 459 458",
                                         "\n608 5 2 1 1 254 255 306 305 407 408 459 99999").encode(),
    }
    for name, data in broken.items():
        with open(os.path.join(w, name), "wb") as f:
            f.write(data)
        rc, out = shard("run", "two_bars_loads.prm", "--set", f"B - Mesh/pulled/mesh file={name}", cwd=w, timeout=60)
        expect(name, (rc, out), 1, rf"B - Mesh/pulled/mesh file = {re.escape(name)}: ")
        lines = [l for l in out.splitlines() if l.startswith("shard: input error")]
        check(f"{name}: one printable line", len(lines) == 1 and all(32 <= ord(c) < 127 for c in lines[0]), out[-800:])
        if name in ("v4_header.msh", "truncated.msh", "garbage.msh", "missing_node.msh"):
            check(f"{name}: names the line of the file", re.search(r"line \d+", out) is not None, out[-800:])


def d05(w):
    expect("width=1e-300", shard("run", scene(BAR), "--set", "B - Mesh/bar/width=1e-300", cwd=w), 1,
           r"B - Mesh/bar/width = 1e-300: element .* zero or negative volume")
    expect("origin=nan, 0, 0", shard("run", scene(BAR), "--set", "B - Mesh/bar/origin=nan, 0, 0", cwd=w), 1,
           r"B - Mesh/bar/origin = nan, 0, 0: 'nan' is not a finite number")
    shutil.copy(scene("two_bars_loads/two_bars_loads.prm"), w)
    with open(os.path.join(w, "degenerate.msh"), "w") as f:
        f.write(bar_msh().replace("608 5 2 1 1 254 255 306 305 407 408 459 458", "608 5 2 1 1 " + "254 " * 7 + "254"))
    for particles in (False, True):
        extra = ["--set", "E - Particles/bodies=pulled"] if particles else []
        expect(f"degenerate.msh{' as particles' if particles else ''}",
               shard("run", "two_bars_loads.prm", "--set", "B - Mesh/pulled/mesh file=degenerate.msh", *extra, cwd=w),
               1, r"B - Mesh/pulled/mesh file = degenerate.msh: element \d+ of body 'pulled'")


def d06(w):
    for key, value, named in (("element size", "1e-300", "element size"), ("length", "4294967296", "element size"),
                              ("width", "1e300", "element size")):
        expect(f"{key}={value}", shard("run", scene(BAR), "--set", f"B - Mesh/bar/{key}={value}", cwd=w, timeout=30), 1,
               rf"B - Mesh/bar/{named} = .*more than 'B - Mesh/max cells' = 4000000")
    expect("a lower bound through max cells",
           shard("run", scene(BAR), "--set", "B - Mesh/max cells=10", cwd=w), 1,
           r"B - Mesh/bar/element size = 0.001: gives 1600 cells, more than 'B - Mesh/max cells' = 10")
    expect("box upper corner=inf",
           shard("run", scene("hybrid_conversion/hybrid_conversion.prm"), "--set",
                 "B - Mesh/block/upper corner=inf, 0.01, 0.01", cwd=w), 1, r"upper corner = inf, 0.01, 0.01: 'inf'")


def d07(w):
    expect("charge position=nan", shard("run", scene("blast/blast.prm"), "--set",
                                         "I - Boundary conditions/blast_near/charge position=nan, 0, 0", cwd=w), 1,
           r"I - Boundary conditions/blast_near/charge position = nan, 0, 0: 'nan' is not a finite number")
    expect("wall point=nan", shard("run", scene(BAR), "--set", "I - Boundary conditions/wall/wall point=nan, 0, 0",
                                   cwd=w), 1, r"I - Boundary conditions/wall/wall point = nan, 0, 0: 'nan'")
    expect("wall normal=0, inf, 0", shard("run", scene(BAR), "--set", "I - Boundary conditions/wall/wall normal=0, inf, 0",
                                          cwd=w), 1, r"wall normal = 0, inf, 0: 'inf'")


def d08(w):
    for expr in ("1/0;0;0", "sqrt(-1);0;0"):
        expect(f"initial velocity={expr}",
               shard("run", scene(BAR), "--set", f"B - Mesh/bar/initial velocity={expr}", "--set",
                     "K - Output/directory=d08", cwd=w), 1,
               r"B - Mesh/bar/initial velocity = .*: is not finite: component 1 is .* at \(.*\) m")
        check(f"initial velocity={expr}: nothing written", not os.path.exists(os.path.join(w, "d08")))
    shutil.copy(scene("two_bars_loads/two_bars_loads.prm"), w)
    shutil.copy(scene("two_bars_loads/bar.msh"), w)
    expect("a traction function 1/0", shard("run", "two_bars_loads.prm", "--set",
                                             "I - Boundary conditions/load/function=1/0; 0; 0", cwd=w), 1,
           r"I - Boundary conditions/load/function = 1/0; 0; 0: is not finite")
    # Finite at t = 0, infinite later: the run stops as unstable (exit 3) naming the condition.
    rc, out = shard("run", "two_bars_loads.prm", "--set", "I - Boundary conditions/load/function=exp(t*1e12); 0; 0",
                    "--set", "J - Time integration/max steps=5", "--set", "K - Output/directory=d08b", *SHORT, cwd=w)
    expect("a traction function exp(t*1e12)", (rc, out), 3, r"I - Boundary conditions/load/function = exp\(t\*1e12\).*is not finite")


def d09(w):
    for expr in ("1/0 0 0", "sqrt(-1) 0 0"):
        expect(f"l2_error {expr}", shard("run", scene(BAR), "--set", f"L - Quantities/quantities=q = l2_error all {expr}",
                                         "--set", "K - Output/directory=d09", cwd=w), 1,
               r"L - Quantities/quantities = .*: the exact displacement is not finite")
        check(f"l2_error {expr}: nothing written", not os.path.exists(os.path.join(w, "d09")))


CONFLICT = """subsection B - Mesh
  set body names = bar
  subsection bar
    set shape = rod
    set length = 0.1
    set width = 0.004
    set element size = 0.002
    set material = steel
  end
end
subsection C - Materials
  set material names = steel
  subsection steel
    set model = elastic
  end
end
subsection I - Boundary conditions
  set condition names = piston, hold
  subsection piston
    set type = velocity
    set body = bar
    set boundary id = {piston}
    set components = x
    set function = 5; 0; 0
  end
  subsection hold
    set type = fixed
    set body = bar
    set boundary id = {hold}
    set components = {hold_components}
  end
end
subsection J - Time integration
  set max steps = 10
end
subsection K - Output
  set directory = out
  set progress interval = 0
  set fields = false
end
"""


def d10(w):
    with open(os.path.join(w, "conflict.prm"), "w") as f:
        f.write(CONFLICT.format(piston=0, hold=0, hold_components="x"))
    expect("velocity and fixed on the same face", shard("run", "conflict.prm", cwd=w), 1,
           r"conflict\.prm:\d+: I - Boundary conditions/hold/type = fixed: conflicts with condition 'piston' "
           r"\(velocity\): both set the x velocity of \d+ node\(s\) of body 'bar'")
    # A velocity on the face x- (0) and a fixed face y- (2) share the 3 nodes of their edge.
    with open(os.path.join(w, "edge.prm"), "w") as f:
        f.write(CONFLICT.format(piston=0, hold=2, hold_components="x"))
    expect("velocity and fixed sharing edge nodes", shard("run", "edge.prm", cwd=w), 1,
           r"hold/type = fixed: conflicts with condition 'piston' \(velocity\): both set the x velocity of 3 "
           r"node\(s\) of body 'bar' \(boundary ids 0 and 2")
    # Other components of the same face: no conflict.
    with open(os.path.join(w, "ok.prm"), "w") as f:
        f.write(CONFLICT.format(piston=0, hold=0, hold_components="y, z"))
    expect("velocity x and fixed y, z on one face", shard("run", "ok.prm", cwd=w), 0)
    # An energy balance whose terms are all round-off (a smooth piston of 1e-158 m/s: energies of
    # 1e-320 J, denormal): over its bare reference the error is 1 (the audit's D10 symptom); the
    # floor 1e-14 M c^2 of the reference keeps the reported error at round-off.
    with open(os.path.join(w, "tiny.prm"), "w") as f:
        f.write(CONFLICT.format(piston=1, hold=2, hold_components="y").replace("5; 0; 0", "1e-158 * (1 - cos(1e5 * t)); 0; 0"))
    rc, out = shard("run", "tiny.prm", cwd=w)
    expect("a piston of 1e-158 m/s", (rc, out), 0)
    if rc == 0:
        import csv
        with open(os.path.join(w, "out", "history.csv")) as f:
            rows = [{k: float(v) for k, v in r.items()} for r in csv.DictReader(f)]
        worst = max(abs(r["energy_error"]) for r in rows)
        bare = 0.0
        for r in rows:
            ref = max(abs(r["external_work"]) + abs(r["boundary_work"]), r["kinetic_energy"])
            if ref > 0:
                bare = max(bare, abs(r["kinetic_energy"] + r["internal_energy"] - r["external_work"] - r["boundary_work"]) / ref)
        check(f"round-off balance: reported error {worst:.3g} < 1e-6", worst < 1e-6, str(worst))
        check(f"round-off balance: over the bare reference it would be {bare:.3g} > 0.5", bare > 0.5, str(bare))


def d11(w):
    shutil.copy(scene("two_bars_loads/two_bars_loads.prm"), w)
    shutil.copy(scene("two_bars_loads/bar.msh"), w)
    expect("boundary id=99", shard("run", "two_bars_loads.prm", "--set", "I - Boundary conditions/load/boundary id=99",
                                   cwd=w), 1,
           r"I - Boundary conditions/load/boundary id = 99: body 'pulled' has no faces with this id; its boundary ids "
           r"are 1, 2, 3")
    expect("max_radius with boundary id 99", shard("run", scene(BAR), "--set",
                                                   "L - Quantities/quantities=r = max_radius bar z 99", cwd=w), 1,
           r"L - Quantities/quantities = .*has no faces with boundary id 99; its boundary ids are")
    expect("kinetic_energy from > to", shard("run", scene(BAR), "--set",
                                             "L - Quantities/quantities=k = kinetic_energy all x 1 0", cwd=w), 1,
           r"L - Quantities/quantities = .*from 1 is larger than to 0")


def d12(w):
    for i, title in enumerate(("a\x01b", "bell\x07 esc\x1b del\x7f", "latin1 \xe9")):
        rc, out = shard("run", scene(BAR), "--set", f"A - Simulation/title={title}", "--set",
                        "J - Time integration/max steps=2", "--set", f"K - Output/directory=d12_{i}", *SHORT, cwd=w)
        check(f"title {title!r}: exit 0", rc == 0, out[-800:])
        try:
            with open(os.path.join(w, f"d12_{i}", "summary.json"), encoding="utf-8") as f:
                s = json.load(f)
            check(f"title {title!r}: summary.json is JSON and keeps the title", s.get("title") == title, str(s.get("title")))
        except (OSError, ValueError) as e:
            check(f"title {title!r}: summary.json is JSON", False, str(e))
    # Bytes that are not UTF-8 in the file name (a scene copied to such a name).
    name = os.fsdecode(b"scene_\xff\x01.prm")
    shutil.copy(scene(BAR), os.path.join(w, name))
    rc, out = shard("run", name, "--set", "J - Time integration/max steps=2", "--set", "K - Output/directory=d12_file",
                    *SHORT, cwd=w)
    try:
        with open(os.path.join(w, "d12_file", "summary.json"), encoding="utf-8") as f:
            json.load(f)
        check("non-UTF-8 file name: summary.json is JSON", rc == 0, out[-800:])
    except (OSError, ValueError) as e:
        check("non-UTF-8 file name: summary.json is JSON", False, str(e))


def d13(w):
    rc, out = shard("run", w, "--set", "J - Time integration/max steps=3", cwd=w)
    expect("a directory as the scene", (rc, out), 1, r"is a directory, not a parameter file")
    check("a directory as the scene: nothing ran", not os.path.exists(os.path.join(w, "output")))


def d14(w):
    expect("a condition missing from condition names",
           shard("run", scene("contact/bars_head_on.prm"), "--set",
                 "I - Boundary conditions/condition names=left_y, left_z, right_y", cwd=w), 1,
           r"bars_head_on\.prm:\d+: unknown subsection 'right_z' in 'I - Boundary conditions'\. .*listed in "
           r"'I - Boundary conditions/condition names'")
    expect("an unknown section in --set", shard("run", scene(BAR), "--set", "Z - Unknown/x=1", cwd=w), 1,
           r"--set Z - Unknown: unknown subsection 'Z - Unknown'")


def run_rows(path):
    with open(path, "rb") as f:
        return f.read()


def d15(w):
    s = scene("hybrid_conversion/hybrid_conversion.prm")
    for limit in (["--set", "J - Time integration/end time=2e-6"], ["--set", "J - Time integration/max steps=6"]):
        tag = limit[1].split("/")[1].split("=")[0].replace(" ", "_")
        rc, out = shard("run", s, *limit, "--set", f"K - Output/directory=straight_{tag}", *SHORT, cwd=w)
        check(f"{tag}: straight run", rc == 0, out[-800:])
        rc, out = shard("run", s, *limit, "--set", "N - Checkpoint/interval=1", "--set",
                        f"K - Output/directory=cut_{tag}", *SHORT, cwd=w)
        rc, out = shard("run", s, *limit, "--set", f"N - Checkpoint/restart from=cut_{tag}/checkpoint", "--set",
                        f"K - Output/directory=cut_{tag}", *SHORT, cwd=w)
        check(f"{tag}: restart from the last step exits 0", rc == 0, out[-800:])
        a, b = run_rows(os.path.join(w, f"straight_{tag}", "history.csv")), run_rows(os.path.join(w, f"cut_{tag}", "history.csv"))
        check(f"{tag}: history.csv equals the straight run byte for byte", a == b, f"{len(a)} vs {len(b)} bytes")
        with open(os.path.join(w, f"straight_{tag}", "summary.json")) as f:
            sa = json.load(f)
        with open(os.path.join(w, f"cut_{tag}", "summary.json")) as f:
            sb = json.load(f)
        for key in ("steps", "final_time", "status"):
            check(f"{tag}: summary {key} {sb.get(key)} == {sa.get(key)}", sa.get(key) == sb.get(key))


def d16(w):
    s = scene(BAR)
    rc, out = shard("run", s, "--set", "K - Output/directory=d16", "--set", "J - Time integration/max steps=20", *SHORT, cwd=w)
    check("first run", rc == 0, out[-800:])
    before = {n: run_rows(os.path.join(w, "d16", n)) for n in sorted(os.listdir(os.path.join(w, "d16")))
              if os.path.isfile(os.path.join(w, "d16", n))}
    refusals = [["--set", "B - Mesh/bar/initial velocity=1/0;0;0"],
                ["--set", "L - Quantities/quantities=q = l2_error all 1/0 0 0"],
                ["--set", "I - Boundary conditions/wall/boundary id=99"],
                ["--set", "C - Materials/steel/density=nan"]]
    for extra in refusals:
        rc, out = shard("run", s, "--set", "K - Output/directory=d16", *extra, *SHORT, cwd=w)
        check(f"{' '.join(extra[1::2])}: refused (exit {rc})", rc in (1, 3), out[-800:])
        after = {n: run_rows(os.path.join(w, "d16", n)) for n in sorted(os.listdir(os.path.join(w, "d16")))
                 if os.path.isfile(os.path.join(w, "d16", n))}
        check(f"{' '.join(extra[1::2])}: the earlier results are untouched", after == before,
              f"changed: {[n for n in set(before) | set(after) if before.get(n) != after.get(n)]}")


def d17(w):
    s = scene("hybrid_conversion/hybrid_conversion.prm")
    base = ["--set", "N - Checkpoint/interval=5", "--set", "J - Time integration/max steps=20"]
    for damage in ("garbage\n", "shard checkpoint 3\nstep 20\nranks 2\n", ""):
        d = f"d17_{len(damage)}"
        shard("run", s, *base, "--set", f"K - Output/directory={d}", *SHORT, cwd=w)
        with open(os.path.join(w, d, "checkpoint", "checkpoint_00000020.manifest"), "w") as f:
            f.write(damage)
        expect(f"a damaged newest manifest {damage[:12]!r}",
               shard("run", s, "--set", f"N - Checkpoint/restart from={d}/checkpoint", "--set",
                     "J - Time integration/max steps=30", "--set", f"K - Output/directory={d}", *SHORT, cwd=w), 1,
               r"N - Checkpoint/restart from = .*: the newest checkpoint manifest .*checkpoint_00000020\.manifest")
    for name, content in (("history.csv", b"\0" * 5000), ("history.csv", None)):
        d = "d17_nul" if content else "d17_edit"
        shard("run", s, *base, "--set", f"K - Output/directory={d}", *SHORT, cwd=w)
        path = os.path.join(w, d, name)
        if content is None:
            data = bytearray(run_rows(path))
            data[len(data) // 2] = ord("7") if data[len(data) // 2] != ord("7") else ord("8")
            content = bytes(data)
        with open(path, "wb") as f:
            f.write(content)
        expect(f"{d}: {name} changed since the checkpoint",
               shard("run", s, "--set", f"N - Checkpoint/restart from={d}/checkpoint", "--set",
                     "J - Time integration/max steps=30", "--set", f"K - Output/directory={d}", *SHORT, cwd=w), 1,
               r"N - Checkpoint/restart from: the first \d+ bytes of .*history\.csv differ from those at the checkpoint")
        check(f"{d}: {name} left as it was", run_rows(path) == content)


def d18(w):
    expect("--set garbage", shard("run", scene(BAR), "--set", "garbage", cwd=w), 2, "malformed --set 'garbage'")
    expect("density=nan", shard("run", scene(BAR), "--set", "C - Materials/steel/density=nan", cwd=w), 1,
           r"--set C - Materials/steel/density: C - Materials/steel/density = nan: must be a finite number "
           r"\(documented range: > 0\)\. Unit: kg/m\^3\.")
    rc, out = shard("run", scene(BAR), "--set", "C - Materials/steel/density=nan", cwd=w)
    check("density=nan: no deal.II pattern text", "MAX_DOUBLE" not in out, out)
    expect("refinement=9 (an integer pattern)",
           shard("run", scene("hybrid_conversion/hybrid_conversion.prm"), "--set", "B - Mesh/block/refinement=9", cwd=w),
           1, r"B - Mesh/block/refinement = 9: must be a whole number from 0 to 8")


def main():
    global ARGS
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--shard", required=True)
    parser.add_argument("--defect", required=True, help="D01 ... D18, or 'all'")
    parser.add_argument("--root", default=os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", ".."))
    parser.add_argument("--keep", action="store_true", help="keep the scratch directory")
    ARGS = parser.parse_args()
    ARGS.shard = os.path.abspath(ARGS.shard)
    ARGS.root = os.path.abspath(ARGS.root)
    checks = {f"D{i:02d}": globals()[f"d{i:02d}"] for i in range(1, 19)}
    names = sorted(checks) if ARGS.defect == "all" else [ARGS.defect]
    for name in names:
        w = tempfile.mkdtemp(prefix=f"shard_{name}_")
        print(f"== {name} (scratch {w})")
        try:
            checks[name](w)
        finally:
            if not ARGS.keep:
                shutil.rmtree(w, ignore_errors=True)
    failed = RESULTS.count(False)
    print(f"{len(RESULTS) - failed} passed, {failed} failed")
    sys.exit(1 if failed or not RESULTS else 0)


if __name__ == "__main__":
    main()
