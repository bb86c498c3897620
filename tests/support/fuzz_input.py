#!/usr/bin/env python3
# SPDX-License-Identifier: LGPL-2.1-or-later
"""Seeded fuzz test of shard's input handling (standard library only; doc/manual/testing.md).

Every case is one scene of prm/verification/ (the `shard run` scenes; the K&C single-point
scenes under concrete/ run through `shard material-test`, less often) with 1 to 3 mutations:
a `set` value replaced by a token from a dictionary (nan, inf, -1, 0, 1e300, 1e-300, an empty
value, `abc`, a wrong number of components, a broken or non-finite expression, a control
character, a very long string, the value of another key, a number scaled by 1e6, 1e-6 or -1),
the same through `--set`, a deleted or duplicated line, a misspelled key, a dropped `end`, an
unknown subsection, the file truncated at a random byte, a malformed `--set` (`garbage`, `/=1`,
`//=1`, an unknown key, a newline in a value) or, for a scene with a Gmsh file, a damaged copy
of that file. The case is fixed by (--seed, case index) and the sorted scene list alone, so a
case replays with `--case K` (and `--keep DIR` keeps its mutated files and command.sh).

Each case runs in its own temporary directory (the mutated .prm and the other files of the
scene's directory beside it; also the working directory), bounded by
`J - Time integration/max steps=5` (run), `B - Mesh/max cells=200000` (run; leave it out with
--no-max-cells), the output directory inside the case directory, progress lines and plots off,
a wall --timeout (60 s) and an address-space limit --memory-gib (4 GiB). These --set arguments
come after the case's own, so they win.

A case fails on
  (1) an exit code other than 0, 1, 2, 3, a signal, or the timeout;
  (2) output containing Stacktrace, Errc, Additional information, Segmentation, signal,
      terminate called, bad_alloc or Assertion (a raw library dump or a crash);
  (3) exit 0 with a non-finite value in history.csv, a null or non-finite number in
      summary.json, or without history.csv or summary.json;
  (4) a summary.json (any exit code) that is not strict JSON (NaN, Infinity, a raw control
      character in a string);
  (5) exit 1 whose message line (`shard: input error: ...` or `shard: error: ...`) names neither
      a key (`C - Materials/steel/density`, or the name of a key the case changed) nor a file
      (a .prm or .msh name, or `--set`).
Exit 2 (command line) and exit 3 (unstable run) are accepted. Each failure prints seed, case,
scene, the mutations, the command, the exit code, the reasons and the first lines of output;
then the count of cases per exit code and per failure class, and last `fuzz: N passed, M failed`.
Exit code 1 when a case failed. Before the cases, the rules are checked on made-up results
(--self-test runs only that).
"""
import argparse
import concurrent.futures
import glob
import json
import math
import os
import random
import re
import resource
import shlex
import shutil
import signal
import subprocess
import sys
import tempfile
import time

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

# Scenes that take longer to set up (or to run 5 steps) are drawn less often; the rest weigh 1.
# The concrete/ scenes (material-test) share MATERIAL_TEST_SHARE of the cases.
SCENE_WEIGHTS = {
    "penetration/penetration_von_mises.prm": 0.2,
    "stability/fine_particles.prm": 0.3,
    "standing_wave/standing_wave_particles.prm": 0.3,
    "concrete_cylinder/concrete_cylinder.prm": 0.5,
    "weighted_partition/weighted_partition.prm": 0.5,
    "two_bars_loads/two_bars_loads.prm": 2.0,   # the only scene with a Gmsh file
}
MATERIAL_TEST_SHARE = 0.15

FORBIDDEN = ["Stacktrace", "Errc", "Additional information", "Segmentation", "signal",
             "terminate called", "bad_alloc", "Assertion"]
MESSAGE = re.compile(r"^shard: (?:input error|error): ?(.*)$", re.M)
KEY_PATH = re.compile(r"\b[A-N] - [A-Z][A-Za-z ]*/")
FILE_NAME = re.compile(r"\.prm\b|\.msh\b|--set\b")
NON_FINITE = re.compile(r"nan|inf", re.I)

SET_LINE = re.compile(r"^(\s*set\s+)([^=]*?)(\s*=\s*)(.*)$")
SUBSECTION = re.compile(r"^\s*subsection\s+(.*?)\s*(?:#.*)?$")
END = re.compile(r"^\s*end\s*(?:#.*)?$")
NUMBER = re.compile(r"(?<![A-Za-z_0-9.])[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?(?![A-Za-z_0-9.])")

TOKENS = ["nan", "inf", "-inf", "-1", "0", "1e300", "1e-300", "-0", "4294967296", "", "abc", "1,2",
          "nan, 0, 0", "1e300, 0, 0", "x+;0;0", "1/0;0;0", "sqrt(-1);0;0"]
# Tokens for the kind of value a key has now (drawn more often than the whole dictionary, so that
# a value passes the syntax check more often and reaches the checks behind it).
NUMBER_TOKENS = ["nan", "inf", "-inf", "-1", "0", "1e300", "1e-300", "-0", "4294967296"]
POINT_TOKENS = ["nan, 0, 0", "1e300, 0, 0", "inf, 0, 0", "0, -inf, 0", "1,2", "0, 0, 0", "-1, -1, -1",
                "1e-300, 1e-300, 1e-300"]
EXPRESSION_TOKENS = ["x+;0;0", "1/0;0;0", "sqrt(-1);0;0", "nan;0;0", "1e300*1e300;0;0", "0;0", "x+", "1/0",
                     "log(0)", "t/0; 0; 0"]

# Mutation kinds and their weights.
MUTATIONS = [("value", 34), ("override", 12), ("delete", 9), ("duplicate", 6), ("misspell", 9),
             ("drop_end", 3), ("subsection", 5), ("truncate", 3), ("bad_set", 5), ("mesh", 4)]


# ---------------------------------------------------------------------------------------------
# Scenes and mutations

class Scene:
    def __init__(self, path, rel, command):
        self.path = path                      # absolute
        self.rel = rel                        # relative to --scenes
        self.command = command                # "run" or "material-test"
        with open(path, encoding="latin-1") as f:
            self.text = f.read()
        d = os.path.dirname(path)
        self.files = sorted(n for n in os.listdir(d)
                            if not n.endswith(".prm") and os.path.isfile(os.path.join(d, n)))
        self.meshes = [n for n in self.files if n.endswith(".msh")]

    @property
    def output_key(self):
        return "K - Output/directory" if self.command == "run" else "M - Material test/output directory"


def find_scenes(directory, pattern=None):
    """The scenes under directory, sorted; a link to a scene already listed is left out."""
    seen, scenes = set(), []
    for path in sorted(glob.glob(os.path.join(directory, "**", "*.prm"), recursive=True)):
        real = os.path.realpath(path)
        if real in seen:
            continue
        seen.add(real)
        rel = os.path.relpath(path, directory)
        if pattern and pattern not in rel:
            continue
        command = "material-test" if rel.split(os.sep)[0] == "concrete" else "run"
        scenes.append(Scene(os.path.abspath(path), rel, command))
    return scenes


def parse(lines):
    """For each `set` line: (index, path, key, value without comment)."""
    stack, sets = [], []
    for i, line in enumerate(lines):
        if END.match(line):
            if stack:
                stack.pop()
            continue
        m = SUBSECTION.match(line)
        if m:
            stack.append(m.group(1))
            continue
        m = SET_LINE.match(line)
        if m:
            key = m.group(2).strip()
            value = m.group(4).split("#", 1)[0].strip()
            sets.append((i, "/".join(stack + [key]), key, value))
    return sets


def show(value, limit=60):
    """A value for the description: control characters escaped, long strings shortened."""
    r = repr(value)
    return r if len(r) <= limit else f"{r[:limit]}... ({len(value)} characters)"


def scale_numbers(value, factor):
    return NUMBER.sub(lambda m: repr(float(m.group(0)) * factor), value)


def pick_token(rng, sets, current):
    """A bad value for a key whose value is now `current`, and its description."""
    kind = rng.choices(["fixed", "control", "long", "other", "scale", "one number"], [17, 2, 2, 3, 4, 4])[0]
    numbers = list(NUMBER.finditer(current))
    if kind == "one number" and numbers:
        m = rng.choice(numbers)
        token = rng.choice(["nan", "inf", "-inf", "1e300", "1/0", "-1", "0"])
        return current[:m.start()] + token + current[m.end():], f"one number replaced by {token}"
    if kind == "control":
        return rng.choice([current + "\x01", "\x01", "a\x01b"]), "with a control character"
    if kind == "long":
        return rng.choice(["x" * 20000, "9" * 400, ", ".join(["1"] * 5000)]), "a very long string"
    if kind == "other" and len(sets) > 1:
        _, path, _, value = rng.choice(sets)
        return value, f"the value of {path}"
    if kind == "scale" and NUMBER.search(current):
        factor = rng.choice([1e6, 1e-6, -1.0])
        return scale_numbers(current, factor), f"scaled by {factor:g}"
    kind = value_kind(current)
    if kind and rng.random() < 0.6:
        return rng.choice({"number": NUMBER_TOKENS, "point": POINT_TOKENS,
                           "expression": EXPRESSION_TOKENS}[kind]), f"token for {kind}"
    return rng.choice(TOKENS), "token"


def misspell(rng, key):
    if len(key) < 2:
        return key + "x"
    i = rng.randrange(len(key))
    if rng.random() < 0.5 or i == len(key) - 1 or key[i] == key[i + 1]:
        return key[:i] + key[i + 1:]
    return key[:i] + key[i + 1] + key[i] + key[i + 2:]


class Case:
    def __init__(self, index, scene):
        self.index = index
        self.scene = scene
        self.text = scene.text
        self.sets = []            # the case's own --set arguments (before the fixed ones)
        self.files = {}           # damaged copies of the scene's other files: name -> bytes
        self.mutations = []       # in words
        self.keys = set()         # names of the keys the case changed (a message may name them)


def value_kind(value):
    """'number', 'point', 'expression' or None (a name, a list of names, a flag)."""
    if re.fullmatch(r"\s*" + NUMBER.pattern + r"\s*", value):
        return "number"
    if re.fullmatch(r"\s*(?:" + NUMBER.pattern + r"\s*,\s*)+" + NUMBER.pattern + r"\s*", value):
        return "point"
    if ";" in value or re.search(r"[*/()^]|\b[xyzt]\b", value):
        return "expression"
    return None


def pick_set(rng, sets):
    """A `set` line; numbers, points and expressions three times as often as names and flags."""
    return rng.choices(sets, [3 if value_kind(v) else 1 for _, _, _, v in sets])[0]


def content_lines(rng, lines):
    """Lines to delete or duplicate: mostly `set` lines (a `subsection` or an `end` one time in
    five; an unbalanced file stops at the first check, which drop_end and truncate test already)."""
    structure = rng.random() < 0.2
    return [i for i, l in enumerate(lines) if l.strip() and not l.strip().startswith("#")
            and (structure or SET_LINE.match(l))]


def mutate(case, rng, kind):
    lines = case.text.split("\n")
    sets = parse(lines)
    if kind in ("value", "override", "misspell") and not sets:
        kind = "delete"
    if kind == "drop_end" and not any(END.match(l) for l in lines):
        kind = "delete"
    if kind == "mesh" and not case.scene.meshes:
        kind = "value" if sets else "delete"
    if kind == "value":
        i, path, key, value = pick_set(rng, sets)
        token, how = pick_token(rng, sets, value)
        m = SET_LINE.match(lines[i])
        lines[i] = m.group(1) + m.group(2) + m.group(3) + token
        case.keys.add(key)
        case.mutations.append(f"line {i + 1}: {path} = {show(value)} -> {show(token)} ({how})")
    elif kind == "override":
        _, path, key, value = pick_set(rng, sets)
        token, how = pick_token(rng, sets, value)
        arg = f"{path}={token}"
        case.sets += ["--set", arg] if rng.random() < 0.7 else ["--set=" + arg]
        case.keys.add(key)
        case.mutations.append(f"--set {path} = {show(token)} ({how}; the file has {show(value)})")
    elif kind == "delete":
        candidates = content_lines(rng, lines)
        if candidates:
            i = rng.choice(candidates)
            case.mutations.append(f"deleted line {i + 1} {show(lines[i].strip())}")
            del lines[i]
    elif kind == "duplicate":
        candidates = content_lines(rng, lines)
        if candidates:
            i = rng.choice(candidates)
            case.mutations.append(f"duplicated line {i + 1} {show(lines[i].strip())}")
            lines.insert(i + 1, lines[i])
    elif kind == "misspell":
        i, path, key, value = rng.choice(sets)
        wrong = misspell(rng, key)
        m = SET_LINE.match(lines[i])
        lines[i] = m.group(1) + wrong + m.group(3) + m.group(4)
        case.keys.update([key, wrong])
        case.mutations.append(f"line {i + 1}: key {path} misspelled {show(wrong)}")
    elif kind == "drop_end":
        i = rng.choice([i for i, l in enumerate(lines) if END.match(l)])
        case.mutations.append(f"dropped the 'end' of line {i + 1}")
        del lines[i]
    elif kind == "subsection":
        i = rng.randrange(len(lines) + 1)
        name = rng.choice(["Q - Unknown", "bogus", "B - Mesh", "steel"])
        lines[i:i] = [f"subsection {name}", "  set colour = 1", "end"]
        case.keys.add("colour")
        case.mutations.append(f"unknown subsection {show(name)} with 'set colour = 1' at line {i + 1}")
    elif kind == "truncate":
        text = "\n".join(lines)
        n = rng.randrange(len(text)) if text else 0
        case.mutations.append(f"truncated at byte {n} of {len(text)}")
        lines = text[:n].split("\n")
    elif kind == "bad_set":
        what = rng.choice(["garbage", "/=1", "//=1", "unknown section", "unknown key", "newline"])
        if what in ("garbage", "/=1", "//=1"):
            arg = what
        elif what == "unknown section":
            arg = "Z - Nothing/key=1"
        elif what == "unknown key" and sets:
            _, path, key, _ = rng.choice(sets)
            wrong = misspell(rng, key)
            arg = path[:len(path) - len(key)] + wrong + "=1"
            case.keys.add(wrong)
        elif sets:
            _, path, key, value = rng.choice(sets)
            arg = f"{path}={value}\n" + rng.choice(["set injected = 1", "end", "subsection x"])
            case.keys.add(key)
        else:
            arg = "garbage"
        case.sets += ["--set", arg]
        case.mutations.append(f"--set {show(arg)} ({what})")
    elif kind == "mesh":
        name = rng.choice(case.scene.meshes)
        data = case.files.get(name)
        if data is None:
            with open(os.path.join(os.path.dirname(case.scene.path), name), "rb") as f:
                data = f.read()
        how = rng.choice(["truncate", "garbage line", "version 4.1", "binary"])
        if how == "truncate":
            n = rng.randrange(len(data))
            data, desc = data[:n], f"truncated at byte {n} of {len(data)}"
        elif how == "garbage line":
            ml = data.split(b"\n")
            k = rng.randrange(len(ml))
            ml[k] = rng.choice([b"garbage", b"1e300 nan inf", b"-1 -1 -1 -1", b""])
            data, desc = b"\n".join(ml), f"line {k + 1} replaced by {ml[k]!r}"
        elif how == "version 4.1":
            data, desc = data.replace(b"2.2 0 8", b"4.1 0 8", 1), "header says version 4.1"
        else:
            n = rng.randrange(len(data))
            blob = bytes(rng.randrange(256) for _ in range(64))
            data, desc = data[:n] + blob + data[n + 64:], f"64 random bytes at byte {n}"
        case.files[name] = data
        case.keys.add(name)
        case.mutations.append(f"mesh file {name}: {desc}")
    case.text = "\n".join(lines)


def make_case(scenes, seed, index, mutations=True):
    """Case `index` of `seed`: a scene and 1 to 3 mutations (none when mutations is False)."""
    rng = random.Random(f"shard-fuzz:{seed}:{index}")
    run = [s for s in scenes if s.command == "run"]
    mt = [s for s in scenes if s.command == "material-test"]
    wr = [SCENE_WEIGHTS.get(s.rel, 1.0) for s in run]
    if mt and run:
        share = MATERIAL_TEST_SHARE
        weights = [w * (1 - share) / sum(wr) for w in wr] + [share / len(mt)] * len(mt)
    else:
        weights = wr + [1.0] * len(mt)
    scene = rng.choices(run + mt, weights)[0]
    case = Case(index, scene)
    if mutations:
        # A scene with a Gmsh file gets its file damaged more often (the only way to test the reader).
        kinds, w = zip(*[(k, 25 if k == "mesh" and scene.meshes else v) for k, v in MUTATIONS])
        for _ in range(rng.randint(1, 3)):
            mutate(case, rng, rng.choices(kinds, w)[0])
    return case


# ---------------------------------------------------------------------------------------------
# Running a case

def fixed_sets(args, scene, outdir):
    sets = ["--set", f"{scene.output_key}={outdir}"]
    if scene.command == "run":
        sets += ["--set", "J - Time integration/max steps=5", "--set", "K - Output/progress interval=0",
                 "--set", "K - Output/fragment plots=false"]
        if not args.no_max_cells:
            sets += ["--set", "B - Mesh/max cells=200000"]
    else:
        sets += ["--set", "M - Material test/plot=false"]
    return sets


def quote(arg, limit=None):
    """Shell quoting that shows control characters as $'\\x01' (and shortens long arguments)."""
    if limit and len(arg) > limit:
        return quote(arg[:limit]) + f"...({len(arg)} characters)"
    if any(ord(c) < 32 or ord(c) == 127 for c in arg):
        body = "".join(c if 32 <= ord(c) < 127 and c not in "'\\" else
                       {"\n": "\\n", "\t": "\\t", "'": "\\'", "\\": "\\\\"}.get(c, f"\\x{ord(c):02x}")
                       for c in arg)
        return f"$'{body}'"
    return shlex.quote(arg)


def limit_memory(nbytes):
    def apply():
        resource.setrlimit(resource.RLIMIT_AS, (nbytes, nbytes))
    return apply


def run_case(args, case, base):
    """Writes the case into its directory, runs it and returns the result dict."""
    d = os.path.join(base, f"case_{case.index:05d}")
    os.makedirs(d)
    src = os.path.dirname(case.scene.path)
    for name in case.scene.files:
        if name in case.files:
            with open(os.path.join(d, name), "wb") as f:
                f.write(case.files[name])
        else:
            shutil.copyfile(os.path.join(src, name), os.path.join(d, name))
    prm = os.path.join(d, os.path.basename(case.scene.path))
    with open(prm, "w", encoding="latin-1", newline="") as f:
        f.write(case.text)
    outdir = os.path.join(d, "out")
    cmd = []
    if args.np > 0:
        cmd = [args.mpiexec] + args.mpiexec_flags.split() + ["-np", str(args.np)]
    cmd += [args.shard, case.scene.command, prm] + case.sets + fixed_sets(args, case.scene, outdir)
    with open(os.path.join(d, "command.sh"), "w") as f:
        f.write("#!/bin/bash\n# The exact command of this case (bash for the $'..' quoting).\n"
                "cd " + shlex.quote(d) + " && OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1 "
                "DEAL_II_NUM_THREADS=1 exec " + " ".join(quote(a) for a in cmd) + "\n")
    env = dict(os.environ, OMPI_ALLOW_RUN_AS_ROOT="1", OMPI_ALLOW_RUN_AS_ROOT_CONFIRM="1",
               DEAL_II_NUM_THREADS="1")
    start = time.monotonic()
    p = subprocess.Popen(cmd, cwd=d, env=env, stdin=subprocess.DEVNULL, stdout=subprocess.PIPE,
                         stderr=subprocess.STDOUT, start_new_session=True,
                         preexec_fn=limit_memory(int(args.memory_gib * 2**30)))
    try:
        out, _ = p.communicate(timeout=args.timeout)
        code = p.returncode
    except subprocess.TimeoutExpired:
        try:
            os.killpg(p.pid, signal.SIGKILL)
        except ProcessLookupError:
            pass
        out, _ = p.communicate()
        code = None
    result = {"dir": d, "cmd": cmd, "code": code, "output": out.decode("utf-8", errors="replace"),
              "seconds": time.monotonic() - start}
    result.update(read_output(outdir))
    return result


def read_output(outdir):
    """history.csv and summary.json of the run, as text (None when absent)."""
    r = {}
    for key, name in (("history", "history.csv"), ("summary", "summary.json")):
        path = os.path.join(outdir, name)
        if os.path.isfile(path):
            with open(path, "rb") as f:
                r[key] = f.read().decode("utf-8", errors="replace")
        else:
            r[key] = None
    return r


# ---------------------------------------------------------------------------------------------
# The rules

def strict_json(text):
    def refuse(name):
        raise ValueError(f"non-standard constant {name}")
    return json.loads(text, parse_constant=refuse)


def bad_numbers(obj, where=""):
    """Paths of null and non-finite numbers in a parsed JSON value."""
    if obj is None:
        return [where or "(top)"]
    if isinstance(obj, float) and not math.isfinite(obj):
        return [where]
    if isinstance(obj, dict):
        return [p for k, v in obj.items() for p in bad_numbers(v, f"{where}/{k}" if where else k)]
    if isinstance(obj, list):
        return [p for k, v in enumerate(obj) for p in bad_numbers(v, f"{where}[{k}]")]
    return []


def non_finite_cells(history):
    """(row, column, text) of the non-finite cells of history.csv (row 1: the first data row)."""
    lines = history.splitlines()
    header = [h.strip() for h in lines[0].split(",")] if lines else []
    found = []
    for r, line in enumerate(lines[1:], start=1):
        for c, cell in enumerate(line.split(",")):
            cell = cell.strip()
            try:
                bad = not math.isfinite(float(cell))
            except ValueError:
                bad = bool(NON_FINITE.search(cell))
            if bad:
                found.append((r, header[c] if c < len(header) else str(c + 1), cell))
    return found


def judge(result, keys=(), unmodified=False):
    """The failure reasons of a result: a list of (class, text); empty when the case passes.
    An unmodified scene must also complete (exit 0)."""
    code, out = result["code"], result["output"]
    reasons = []
    if unmodified and code != 0:
        m = MESSAGE.search(out)
        reasons.append(("unmodified scene not completed", f"the unmodified scene ended with exit code "
                        f"{exit_label(code)}, not 0" + (f": {show(m.group(0), 300)}" if m else "")))
    if code is None:
        reasons.append(("timeout", "no exit within the timeout"))
    elif code < 0:
        name = signal.Signals(-code).name if -code in signal.Signals._value2member_map_ else str(-code)
        reasons.append((f"signal {name}", f"killed by signal {name}"))
    elif code not in (0, 1, 2, 3):
        reasons.append((f"exit {code}", f"exit code {code} (allowed: 0, 1, 2, 3)"))
    for word in FORBIDDEN:
        if word in out:
            reasons.append((f"output '{word}'", f"output contains '{word}'"))
    if result["summary"] is not None:
        try:
            summary = strict_json(result["summary"])
        except ValueError as e:
            summary = None
            reasons.append(("invalid summary.json", f"summary.json is not valid JSON: {e}"))
    if code == 0:
        if result["history"] is None:
            reasons.append(("exit 0 without history.csv", "exit 0 but no history.csv"))
        else:
            cells = non_finite_cells(result["history"])
            if cells:
                r, c, t = cells[0]
                reasons.append(("exit 0 non-finite history.csv",
                                f"exit 0 with {len(cells)} non-finite cell(s) in history.csv, "
                                f"first row {r} column {c}: {t}"))
        if result["summary"] is None:
            reasons.append(("exit 0 without summary.json", "exit 0 but no summary.json"))
        elif summary is not None:
            bad = bad_numbers(summary)
            if bad:
                reasons.append(("exit 0 null in summary.json", "exit 0 with null or non-finite values "
                                f"in summary.json: {', '.join(bad[:5])}"))
    if code == 1:
        m = MESSAGE.search(out)
        if not m:
            reasons.append(("exit 1 without message", "exit 1 without a 'shard: input error:' or "
                            "'shard: error:' line"))
        else:
            text = m.group(1)
            named = KEY_PATH.search(text) or FILE_NAME.search(text) or \
                any(k and re.search(r"(?<![\w])" + re.escape(k) + r"(?![\w])", text) for k in keys)
            if not named:
                reasons.append(("exit 1 names no key or file",
                                f"exit 1 and the message names no key or file: {show(m.group(0), 200)}"))
    return reasons


def self_test():
    """The rules on made-up results: each bad result must fail, the good ones pass."""
    good_history = "time,kinetic energy\n0,1\n1e-6,0.5\n"
    good_summary = '{"status": "completed", "results": {"mass": 1.5}, "steps": 5}'

    def res(code, output="", history=good_history, summary=good_summary):
        return {"code": code, "output": output, "history": history, "summary": summary}
    bad = {
        "segfault": res(-11),
        "exit 139": res(139),
        "timeout": res(None),
        "Errc": res(1, "shard: input error: x.prm:3: B - Mesh/a = x+: Errc: 3\n"),
        "stack": res(1, "shard: error: B - Mesh/a\n--- Stacktrace ---\n"),
        "nan history": res(0, history="time,e\n0,1\n1e-6,-nan\n"),
        "inf history": res(0, history="time,e\n0,inf\n"),
        "null summary": res(0, summary='{"results": {"mass": null}}'),
        "NaN summary": res(3, summary='{"results": {"mass": NaN}}'),
        "control character": res(1, "shard: input error: a.prm:1: A - Simulation/title: x\n",
                                 summary='{"title": "a\x01b"}'),
        "no summary": res(0, summary=None),
        "no key": res(1, "shard: error: something went wrong\n"),
        "no message": res(1, "run stopped: energy error 1\n"),
    }
    good = {
        "completed": res(0),
        "refusal": res(1, "shard: input error: misspelled_key.prm:18: unknown key 'densty'. Did you mean\n"),
        "--set": res(1, "shard: input error: --set C - Materials/steel/densty: no\n", summary=None),
        "key path": res(1, "shard: input error: default: B - Mesh/bar/length = 0: must be > 0\n"),
        "mesh": res(1, "shard: error: bar.msh:12: not a Gmsh file\n"),
        "key name": res(1, "shard: input error: key 'density' is wrong\n", summary=None),
        "command line": res(2, "shard: unexpected argument 'x'.\n", summary=None),
        "unstable": res(3, "shard: run stopped: step 3\n"),
    }
    problems = [f"'{n}' passed the rules" for n, r in bad.items() if not judge(r)]
    problems += [f"'{n}' failed the rules: {judge(r, ['density'])}" for n, r in good.items()
                 if judge(r, ["density"])]
    return problems


# ---------------------------------------------------------------------------------------------

def exit_label(code):
    if code is None:
        return "timeout"
    if code < 0:
        try:
            return f"{code} ({signal.Signals(-code).name})"
        except ValueError:
            return str(code)
    return str(code)


def report(args, case, result, reasons, preflight=False):
    what = "preflight" if preflight else f"case {case.index} (seed {args.seed})"
    lines = [f"FAIL  {what}: {case.scene.command} {case.scene.rel}"]
    for m in case.mutations or ["(no mutation)"]:
        lines.append(f"      mutation: {m}")
    lines.append("      command: cd " + shlex.quote(result["dir"]) + " && "
                 + " ".join(quote(a, 300) for a in result["cmd"]))
    lines.append(f"      exit code: {exit_label(result['code'])} after {result['seconds']:.1f} s")
    for _, text in reasons:
        lines.append(f"      why: {text}")
    out = result["output"].splitlines()
    for line in out[:args.lines]:
        lines.append("      | " + (line if len(line) <= 300 else line[:300] + "..."))
    if len(out) > args.lines:
        lines.append(f"      | ... ({len(out) - args.lines} more lines)")
    replay = f"python3 tests/support/fuzz_input.py --shard {shlex.quote(args.shard)}"
    if preflight or not case.mutations:
        replay += f" --unmodified --scene {shlex.quote(case.scene.rel)} --keep /tmp/fuzz_case"
    else:
        replay += f" --seed {args.seed} --case {case.index} --keep /tmp/fuzz_case"
        if args.scene:
            replay += f" --scene {shlex.quote(args.scene)}"
    if args.no_max_cells:
        replay += " --no-max-cells"
    lines.append(f"      replay: {replay}")
    return "\n".join(lines)


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--shard", help="the shard binary")
    ap.add_argument("--seed", type=int, default=2026)
    ap.add_argument("--cases", type=int, default=300, help="run cases 0 .. CASES-1")
    ap.add_argument("--case", type=int, action="append", help="run only this case index (repeatable)")
    ap.add_argument("--scenes", default=os.path.join(ROOT, "prm", "verification"))
    ap.add_argument("--scene", help="only scenes whose path contains this (changes the cases)")
    ap.add_argument("--unmodified", action="store_true",
                    help="run every scene once without mutation (each must pass)")
    ap.add_argument("--jobs", type=int, default=os.cpu_count() or 1)
    ap.add_argument("--timeout", type=float, default=60.0, help="wall seconds per case")
    ap.add_argument("--memory-gib", type=float, default=4.0, help="address-space limit per case")
    ap.add_argument("--np", type=int, default=0, help="ranks through --mpiexec; 0: one rank, no mpiexec")
    ap.add_argument("--mpiexec", default="mpiexec")
    ap.add_argument("--mpiexec-flags", default="--allow-run-as-root --oversubscribe")
    ap.add_argument("--no-max-cells", action="store_true", help="do not pass 'B - Mesh/max cells'")
    ap.add_argument("--keep", help="keep the directories of failing (with --case: all) cases here")
    ap.add_argument("--lines", type=int, default=12, help="lines of output shown per failure")
    ap.add_argument("--verbose", action="store_true", help="print every case")
    ap.add_argument("--self-test", action="store_true", help="only check the rules on made-up results")
    ap.add_argument("--list", action="store_true", help="print the cases (scene, mutations) without running")
    args = ap.parse_args()

    problems = self_test()
    if problems:
        for p in problems:
            print(f"FAIL  self-test: {p}")
        print(f"fuzz: 0 passed, {len(problems)} failed")
        return 1
    if args.self_test:
        print("ok    self-test: the rules flag every made-up failure and pass the good results")
        return 0
    if not args.shard and not args.list:
        ap.error("--shard is required")
    args.shard = os.path.abspath(args.shard or "shard")
    scenes = find_scenes(args.scenes, args.scene)
    if not scenes:
        ap.error(f"no scenes under {args.scenes}")
    if args.unmodified:
        cases = [Case(k, s) for k, s in enumerate(scenes)]
    else:
        indices = args.case if args.case else range(args.cases)
        cases = [make_case(scenes, args.seed, k) for k in indices]
    if args.list:
        for case in cases:
            print(f"case {case.index}: {case.scene.command} {case.scene.rel}")
            for m in case.mutations:
                print(f"      mutation: {m}")
            if case.sets:
                print("      --set arguments: " + " ".join(quote(a, 80) for a in case.sets))
        return 0
    keep_all = bool(args.case) or args.unmodified
    if args.keep:
        os.makedirs(args.keep, exist_ok=True)
    base = tempfile.mkdtemp(prefix="shard_fuzz_", dir=args.keep)
    print(f"fuzz: {len(cases)} cases of seed {args.seed} over {len(scenes)} scenes, {args.jobs} jobs, "
          f"timeout {args.timeout:g} s, {args.memory_gib:g} GiB; {args.shard}", flush=True)

    start = time.monotonic()
    failures, codes, classes = [], {}, {}

    def one(case):
        result = run_case(args, case, base)
        return case, result, judge(result, case.keys, unmodified=not case.mutations)

    # Preflight: the first scene of each command, unmodified, must complete with the fixed --set
    # arguments; otherwise every case would be refused for them and the fuzzing would test nothing.
    if not args.unmodified and not args.case:
        firsts = [next(s for s in scenes if s.command == c) for c in ("run", "material-test")
                  if any(s.command == c for s in scenes)]
        bad = [r for r in map(one, [Case(k, s) for k, s in enumerate(firsts)]) if r[2]]
        shutil.rmtree(base, ignore_errors=True)
        if bad:
            for case, result, reasons in bad:
                print(report(args, case, result, reasons, preflight=True))
            print("fuzz: an unmodified scene does not complete with the fixed --set arguments (for a shard "
                  "without 'B - Mesh/max cells': --no-max-cells); no case was run")
            print(f"fuzz: 0 passed, {len(bad)} failed")
            return 1
        base = tempfile.mkdtemp(prefix="shard_fuzz_", dir=args.keep)

    results, step = [], max(100, len(cases) // 10)
    with concurrent.futures.ThreadPoolExecutor(max_workers=max(1, args.jobs)) as pool:
        for r in concurrent.futures.as_completed([pool.submit(one, c) for c in cases]):
            results.append(r.result())
            if len(results) % step == 0 and len(results) < len(cases):
                print(f"fuzz: {len(results)} of {len(cases)} cases run, {sum(1 for x in results if x[2])} "
                      f"failed so far ({time.monotonic() - start:.0f} s)", flush=True)
    results.sort(key=lambda r: r[0].index)
    for case, result, reasons in results:
        label = exit_label(result["code"])
        codes[label] = codes.get(label, 0) + 1
        if reasons:
            failures.append(case)
            print(report(args, case, result, reasons), flush=True)
            for cls, _ in reasons:
                classes.setdefault(cls, []).append(case.index)
        elif args.verbose:
            m = MESSAGE.search(result["output"])
            print(f"ok    case {case.index}: {case.scene.rel}, exit {label}, {result['seconds']:.1f} s; "
                  + "; ".join(case.mutations) + (f"\n      {show(m.group(0), 300)}" if m else ""))
        if not (args.keep and (reasons or keep_all)):
            shutil.rmtree(result["dir"], ignore_errors=True)
    if not (args.keep and os.listdir(base)):
        shutil.rmtree(base, ignore_errors=True)
    elif args.keep:
        print(f"fuzz: kept the case directories in {base}")

    slowest = max(results, key=lambda r: r[1]["seconds"])
    print(f"fuzz: {time.monotonic() - start:.1f} s; slowest case {slowest[0].index} "
          f"({slowest[0].scene.rel}) {slowest[1]['seconds']:.1f} s")
    order = sorted(codes, key=lambda c: (c == "timeout", int(c.split()[0]) if c != "timeout" else 0))
    print("fuzz: cases per exit code: " + ", ".join(f"{c}: {codes[c]}" for c in order))
    for cls in sorted(classes, key=lambda c: -len(classes[c])):
        ks = classes[cls]
        also = f" (also {', '.join(map(str, ks[1:6]))}{', ...' if len(ks) > 6 else ''})" if len(ks) > 1 else ""
        print(f"fuzz: failure class {cls}: {len(ks)} case(s), e.g. case {ks[0]}{also}")
    print(f"fuzz: {len(cases) - len(failures)} passed, {len(failures)} failed")
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
