#!/usr/bin/env python3
# SPDX-License-Identifier: LGPL-2.1-or-later
"""Closed-form checks of `contrib/utilities/hanchak_report.py` (doc/validation.md, "Where the
resistance is missing", "The sweep at 4 mm"):
1. a history of constant deceleration a gives F = m a in every window, at the window's mid depth;
2. the cavity-expansion estimate: linear in the crater (F(a) = F(2a) / 2), zero behind the slab,
   and Hill's static cavity pressure (2/3) Y (1 + ln(E / (3 (1 - nu) Y))) at V = 0 for the von
   Mises target; the concrete static term pi a^2 S f'c with S = 82.6 (f'c/MPa)^-0.544;
3. the perforation rules on histories built by hand: a tail past the rear face ('tail'); a tip
   out for 150 us at a constant speed ('levelled'); the same with 2 % of speed lost in the last
   100 us, a tip out for only 50 us, and a tip still in the slab (not perforated).
Exits non-zero on the first failure."""
import csv
import math
import os
import sys
import tempfile

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..", "contrib", "utilities"))
import hanchak_report as h  # noqa: E402


def check(name, got, want, rtol):
    ok = abs(got - want) <= rtol * abs(want)
    print(f"{'ok  ' if ok else 'FAIL'} {name}: {got:.9g} against {want:.9g} (rtol {rtol:g})")
    return ok


def history(v_end, loss, t_exit, tail_out=False):
    """Rows of a projectile whose tip passes the rear face at t_exit (s) and whose speed falls
    linearly by `loss` (relative) over the last 100 us of a 1 ms run, ending at v_end."""
    rows = []
    for i in range(1001):
        t = i * 1e-6
        v = v_end * (1 + loss * max(0.0, (1e-3 - t) / 1e-4) if t > 0.9e-3 else 1 + loss)
        tip = h.REAR - 0.01 if t >= t_exit else h.REAR + 0.01
        tail = h.REAR - 0.001 if tail_out and i == 1000 else h.REAR + 0.05
        rows.append({"time": str(t), "v_projectile": str(-v), "tip_z": str(tip), "tail_z": str(tail)})
    return rows


def check_perforation():
    cases = [("tail past the rear face", history(200.0, 0.0, 0.5e-3, tail_out=True), (True, "tail")),
             ("tip out 500 us, speed constant", history(200.0, 0.0, 0.5e-3), (True, "levelled")),
             ("tip out 150 us, 0.5 % lost in 100 us", history(200.0, 0.005, 0.85e-3), (True, "levelled")),
             ("tip out, 2 % lost in the last 100 us", history(200.0, 0.02, 0.5e-3), (False, None)),
             ("tip out for 50 us only", history(200.0, 0.0, 0.95e-3), (False, None)),
             ("tip still in the slab", history(200.0, 0.0, 2e-3), (False, None))]
    good = True
    for name, rows, want in cases:
        got = h.perforation(rows)
        ok = got == want
        print(f"{'ok  ' if ok else 'FAIL'} perforation, {name}: {got} against {want}")
        good &= ok
    return good


def main():
    good = True
    v0, acc, dt = 434.0, 2.0e5, 1.0e-7  # m/s, m/s^2 (a 100 kN force on 0.5 kg), s
    with tempfile.TemporaryDirectory() as d:
        with open(os.path.join(d, "history.csv"), "w", newline="") as f:
            w = csv.writer(f)
            w.writerow(["time", "v_projectile", "tip_z"])
            for i in range(1500):
                t = i * dt
                w.writerow([t, -(v0 - acc * t), -(v0 * t - 0.5 * acc * t * t)])
        f = h.resisting_force(d)
        good &= len(f) > 5
        for depth, v, force in f:
            good &= check(f"F at {depth * 1e3:.2f} mm", force, 0.500 * acc, 1e-9)
            # The speed reported is the mean of the window's ends: v0 - a t_mid on a parabola.
            t_mid = (v0 - math.sqrt(v0 * v0 - 2 * acc * depth)) / acc
            good &= check("speed at the window", v, v0 - acc * t_mid, 1e-3)
    a = h.RADIUS
    good &= check("crater: F(a) = F(2a) / 2", h.forrestal_force(a, 400.0), 0.5 * h.forrestal_force(2 * a, 400.0), 1e-12)
    good &= h.forrestal_force(0.2, 400.0) == 0.0 and h.forrestal_force(0.0, 400.0) == 0.0
    y, e, nu = 300e6, 30e9, 0.19
    good &= check("Hill static cavity pressure", h.forrestal_force(0.05, 0.0, von_mises=(y, e, nu)) / (math.pi * a * a),
                  2.0 / 3.0 * y * (1 + math.log(e / (3 * (1 - nu) * y))), 1e-12)
    good &= check("concrete static term S f'c", h.forrestal_force(0.05, 0.0) / (math.pi * a * a),
                  82.6 * 48.0 ** -0.544 * 48e6, 1e-12)
    good &= check_perforation()
    print("hanchak_force_test:", "passed" if good else "FAILED")
    return 0 if good else 1


if __name__ == "__main__":
    sys.exit(main())
