#!/usr/bin/env python3
# SPDX-License-Identifier: LGPL-2.1-or-later
"""Closed-form checks of `contrib/utilities/hanchak_report.py force` (doc/validation.md, "Where the
resistance is missing"):
1. a history of constant deceleration a gives F = m a in every window, at the window's mid depth;
2. the cavity-expansion estimate: linear in the crater (F(a) = F(2a) / 2), zero behind the slab,
   and Hill's static cavity pressure (2/3) Y (1 + ln(E / (3 (1 - nu) Y))) at V = 0 for the von
   Mises target; the concrete static term pi a^2 S f'c with S = 82.6 (f'c/MPa)^-0.544.
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
    print("hanchak_force_test:", "passed" if good else "FAILED")
    return 0 if good else 1


if __name__ == "__main__":
    sys.exit(main())
