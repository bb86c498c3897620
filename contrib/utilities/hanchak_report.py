#!/usr/bin/env python3
# SPDX-License-Identifier: LGPL-2.1-or-later
"""Results of the Hanchak slab perforation (prm/examples/hanchak/hanchak.prm, doc/validation.md):

    hanchak_report.py run OUTPUT_DIR [--json FILE]     one run: residual velocity, exit time,
                                                       front crater, scab, fragments
    hanchak_report.py sweep CSV PNG [--tests FILE]     Recht-Ipson fit of residual_velocity.csv and
                                                       the plot (numpy, matplotlib)
    hanchak_report.py force PNG OUTPUT_DIR[=LABEL] ... the projectile's resisting force against the
                                                       tip depth, with the cavity-expansion estimate

Definitions of one run (slab 178 mm thick between z = -0.178 and 0, shot along -z):
  residual velocity  the projectile's mean velocity -v_z at the end of the run if it perforated,
             0 otherwise (stopped or stuck in the slab). Perforated: its tail (the largest z of
             the projectile) has passed the rear face z = -0.178 (rule 'tail'), or its tip passed
             the rear face at least 100 us before the end and its speed changed by less than 1 %
             over those last 100 us (rule 'levelled': the deceleration has ended, the tail runs
             free in the scab crater). A run that did not complete (summary status 'unstable':
             stopped with a diagnostic) and did not perforate by these rules has no residual
             velocity (empty; the sweep's fit skips it); its status is reported;
  exit time  the first history row at which the tip (the smallest z) passes the rear face;
  front crater / scab  at the last field output, the particles on the front face (z = 0) or the
             rear face (z = -0.178) in the reference configuration that have moved more than
             one particle spacing (the run's 'B - Mesh/slab/element size') from their place: their
             face area (particle volume / half a layer) as the diameter of the circle of that area, and their
             largest distance from the shot line;
  fragments  from fragments.csv at the last output: count, the slab (heaviest), the debris
             (everything but the slab and the projectile), its largest piece and fastest speed;
             from summary.json the dust fraction (debris of fewer than 'K - Output/dust
             particles' particles over the debris mass);
  crater / scab mass  the debris (fragment_statistics.csv, debris = 1) whose origin (centre of
             mass in the reference configuration, z0) lies in the front half (z0 > -0.089) or
             the rear half of the slab: the material lost on each side;
  tunnel force  the mean resisting force (below) with the tip 2 a to 100 mm deep, the
             cavity-expansion estimate there for the run's f'c and rho, and their ratio.

Resisting force: F = -m dv/dt of the projectile (m = 0.500 kg), the velocity difference over
windows of one particle spacing (the run's) of tip travel, against the tip depth. The estimate is the
empirical cavity-expansion model of Forrestal et al. (1994, IJIE 15, 395-405) for an ogive nose:
F = c z in the crater region (tip depth z < 2 a), F = pi a^2 (S f'c + N* rho V^2) in the tunnel,
with N* = (8 psi - 1) / (24 psi^2) for the nose calibre radius psi (Forrestal et al. 1996, IJIE 18,
465-476) and S = 82.6 (f'c / MPa)^-0.544 (Frew et al. 1998, IJIE 21, 489-497); c makes F
continuous at z = 2 a. It holds for semi-infinite targets: in the slab it applies from about 2 a
deep until the rear-face release (roughly the last three calibres), so it is a yardstick of the
resistance a model offers while the nose is embedded, not a prediction of the residual velocity.
With --von-mises Y,E,NU (a target of elastic-perfectly plastic material) the tunnel force is the
spherical cavity expansion of Hill (1950) with a compressible elastic zone (Forrestal and Luk 1988),
sigma_s = (2/3) Y (1 + ln(E / (3 (1 - nu) Y))), plus 1.5 N* rho V^2: F = pi a^2 (sigma_s + 1.5 N* rho V^2).

Recht-Ipson: v_r = a (v_s^p - v_bl^p)^(1/p) for v_s > v_bl, else 0; a, p and v_bl are fitted by
least squares on every run (a in closed form for each (v_bl, p) of a grid search).
"""
import argparse
import csv
import json
import math
import os
import re
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from shard_output import last_fragments, last_pieces, read_vtu  # noqa: E402

REAR, FRONT, SPACING = -0.178, 0.0, 0.004
# The 'levelled' perforation rule: window (s) and largest relative change of the speed in it.
LEVEL_WINDOW, LEVEL_CHANGE = 100e-6, 0.01
# Projectile mass (kg), radius (m), nose calibre radius; concrete density and strength of the scene.
MASS, RADIUS, CRH, RHO, FC = 0.500, 0.0127, 3.0, 2440.0, 48e6


def history(out_dir):
    """The rows of history.csv; a row still being written by a running shard is left out."""
    with open(os.path.join(out_dir, "history.csv")) as f:
        return [r for r in csv.DictReader(f) if None not in r.values()]


def face_damage(out_dir, z_face, spacing):
    """(equivalent diameter, largest radius) of the face particles that moved more than a spacing."""
    area, rmax = 0.0, 0.0
    for piece in last_pieces(out_dir, "particles"):
        a = read_vtu(piece)
        x, d, vol = a["Points"][0], a["displacement"][0], a["volume"][0]
        for i in range(len(vol)):
            X = [x[3 * i + k] - d[3 * i + k] for k in range(3)]
            if abs(X[2] - z_face) > 1e-3 * spacing:
                continue
            if math.sqrt(sum(d[3 * i + k] ** 2 for k in range(3))) > spacing:
                area += vol[i] / (0.5 * spacing)
                rmax = max(rmax, math.hypot(X[0], X[1]))
    return 2 * math.sqrt(area / math.pi), rmax


def lost_mass(out_dir):
    """(crater mass, scab mass): debris mass with its origin in the front or rear half (kg)."""
    path = os.path.join(out_dir, "fragment_statistics.csv")
    if not os.path.exists(path):
        return None, None
    front = rear = 0.0
    with open(path) as f:
        for r in csv.DictReader(f):
            if r["debris"] != "1" or "z0" not in r:
                continue
            if float(r["z0"]) > 0.5 * REAR:
                front += float(r["mass"])
            else:
                rear += float(r["mass"])
    return front, rear


def parameter(out_dir, path):
    """The value of the key at 'A/B/key' in the run's parameters.prm (None if absent)."""
    stack = []
    path_prm = os.path.join(out_dir, "parameters.prm")
    if not os.path.exists(path_prm):
        return None
    with open(path_prm) as f:
        for line in f:
            t = line.split("#")[0].strip()
            if t.startswith("subsection "):
                stack.append(t[len("subsection "):].strip())
            elif t == "end":
                stack.pop()
            else:
                m = re.match(r"set (.*?)\s*=\s*(.*)", t)
                if m and "/".join(stack + [m.group(1).strip()]) == path:
                    return m.group(2).strip()
    return None


def spacing_of(out_dir):
    """The run's particle spacing: 'B - Mesh/slab/element size' (SPACING when absent)."""
    return float(parameter(out_dir, "B - Mesh/slab/element size") or SPACING)


def exit_time_of(rows):
    """Time of the first history row with the tip past the rear face (None: not yet)."""
    return next((float(r["time"]) for r in rows if float(r["tip_z"]) < REAR), None)


def perforation(rows):
    """(perforated, rule) of a history: rule 'tail', 'levelled' or None (module docstring)."""
    last = rows[-1]
    if float(last["tail_z"]) < REAR:
        return True, "tail"
    t_end, v_end = float(last["time"]), -float(last["v_projectile"])
    exit_time = exit_time_of(rows)
    if exit_time is None or exit_time > t_end - LEVEL_WINDOW or v_end <= 0:
        return False, None
    before = next(r for r in reversed(rows) if float(r["time"]) <= t_end - LEVEL_WINDOW)
    if abs(v_end + float(before["v_projectile"])) <= LEVEL_CHANGE * v_end:
        return True, "levelled"
    return False, None


def run_report(out_dir):
    rows = history(out_dir)
    last = rows[-1]
    tail, v = float(last["tail_z"]), -float(last["v_projectile"])
    perforated, rule = perforation(rows)
    exit_time = exit_time_of(rows)
    with open(os.path.join(out_dir, "summary.json")) as f:
        summary = json.load(f)
    spacing = spacing_of(out_dir)
    crater, crater_r = face_damage(out_dir, FRONT, spacing)
    scab, scab_r = face_damage(out_dir, REAR, spacing)
    t, frags = last_fragments(os.path.join(out_dir, "fragments.csv"))
    frags.sort(key=lambda r: -float(r["mass"]))
    # The slab is the heaviest piece; the projectile is the piece of FE nodes only (no particles)
    # whose mass is within 5 % of the projectile's, else the one moving fastest along -z among
    # the three heaviest (a projectile that rebounds moves along +z).
    slab = frags[0]
    whole = [r for r in frags[1:] if int(r["particles"]) == 0 and abs(float(r["mass"]) - MASS) <= 0.05 * MASS]
    projectile = whole[0] if whole else min(frags[:3], key=lambda r: float(r["vz"]))
    debris = [r for r in frags if r is not slab and r is not projectile]
    crater_mass, scab_mass = lost_mass(out_dir)
    status = summary.get("status", "completed")
    residual = v if perforated else (0.0 if status == "completed" else None)
    return {
        "residual_velocity": residual, "status": status, "final_velocity": v, "perforated": perforated,
        "perforation_rule": rule,
        "exit_time": exit_time, "end_time": float(last["time"]), "tail_z": tail,
        "front_crater_diameter": crater, "front_crater_radius_max": crater_r,
        "scab_diameter": scab, "scab_radius_max": scab_r,
        "n_fragments": len(frags), "debris_mass": sum(float(r["mass"]) for r in debris),
        "largest_debris_mass": max([float(r["mass"]) for r in debris] + [0.0]),
        "dust_fraction": summary.get("fragments", {}).get("dust_fraction"),
        "crater_mass": crater_mass, "scab_mass": scab_mass,
        "fastest_debris_speed": max([math.sqrt(sum(float(r[c]) ** 2 for c in ("vx", "vy", "vz"))) for r in debris] + [0.0]),
        "energy_error": summary.get("energy_error"), "max_abs_energy_error": summary.get("max_abs_energy_error"),
        "steps": summary.get("steps"), "wall_time": summary.get("wall_time_s"),
        "particles": summary.get("n_particles"), "elements": summary.get("n_elements"),
        "spacing": spacing,
        "dilation": float(parameter(out_dir, "E - Particles/dilation") or "nan"),
        "bond_criterion": parameter(out_dir, "E - Particles/bond failure/concrete/criterion"),
        "bond_threshold": parameter(out_dir, "E - Particles/bond failure/concrete/threshold"),
        "projectile_material": parameter(out_dir, "B - Mesh/projectile/material"),
        **tunnel_force(out_dir),
    }


def estimate_parameters(out_dir, von_mises=None):
    """The keyword arguments of forrestal_force for a run: f'c and rho of its material 'concrete'
    when it has them (the scene's otherwise), and von_mises as given."""
    return {"fc": float(parameter(out_dir, "C - Materials/concrete/compressive strength") or FC),
            "rho": float(parameter(out_dir, "C - Materials/concrete/density") or RHO),
            "von_mises": von_mises}


def tunnel_force(out_dir, f=None, von_mises=None):
    """Mean resisting force with the tip 2 a to 100 mm deep and the cavity-expansion estimate there
    (estimate_parameters); None when the tip did not get there. @p f: resisting_force(out_dir)
    when already read."""
    mean = tunnel_mean(resisting_force(out_dir) if f is None else f, **estimate_parameters(out_dir, von_mises))
    if mean is None:
        return {"tunnel_force": None, "tunnel_force_estimate": None, "tunnel_force_ratio": None}
    model, est = mean
    return {"tunnel_force": model, "tunnel_force_estimate": est, "tunnel_force_ratio": model / est}


def recht_ipson(vs, vr):
    """(a, p, v_bl, rms) of the least-squares Recht-Ipson fit."""
    best = None
    vmax = max(vs)
    lo = max([s for s, r in zip(vs, vr) if r <= 0] + [0.0])
    hi = min([s for s, r in zip(vs, vr) if r > 0] + [vmax])
    for i in range(401):
        vbl = lo + (hi - lo) * i / 400
        for j in range(1, 121):
            p = 1.0 + 0.05 * (j - 1)
            g = [(s ** p - vbl ** p) ** (1 / p) if s > vbl else 0.0 for s in vs]
            gg = sum(x * x for x in g)
            if gg == 0:
                continue
            a = min(1.0, sum(x * y for x, y in zip(g, vr)) / gg)
            rms = math.sqrt(sum((a * x - y) ** 2 for x, y in zip(g, vr)) / len(vs))
            if best is None or rms < best[3]:
                best = (a, p, vbl, rms)
    return best


def debris_panels(axm, axv, rows):
    """Debris of the sweep: masses (crater, scab, largest fragment) with the dust fraction, and
    the fastest fragment against the striking velocity (a fragment faster than the striking
    velocity is above the dotted line)."""
    def col(name, scale=1.0):
        return [(float(r["striking_velocity"]), float(r[name]) * scale) for r in rows
                if r.get(name) not in (None, "", "None")]
    for name, label, marker in (("debris_mass", "debris", "o"), ("crater_mass", "crater (front half)", "v"),
                                ("scab_mass", "scab (rear half)", "^"), ("largest_debris_mass", "largest fragment", "s")):
        pts = col(name, 1e3)
        if pts:
            axm.plot(*zip(*pts), marker + "-", label=label)
    axm.set_yscale("log")
    axm.set_xlabel("striking velocity (m/s)")
    axm.set_ylabel("mass (g)")
    axm.set_title("debris by origin; dust fraction (right axis)")
    axm.grid(alpha=0.3)
    dust = col("dust_fraction")
    if dust:
        twin = axm.twinx()
        twin.plot(*zip(*dust), "x--", color="k", label="dust fraction")
        twin.set_ylim(0, 1.05)
        twin.set_ylabel("dust mass / debris mass")
        twin.legend(fontsize=8, loc="lower right")
    axm.legend(fontsize=8, loc="upper left")
    fast = col("fastest_debris_speed")
    if fast:
        vmax = max(float(r["striking_velocity"]) for r in rows)
        top = max(max(v for _, v in fast), vmax) * 1.1
        axv.plot(*zip(*fast), "o-", color="tab:red", label="fastest debris fragment")
        axv.plot([0, top], [0, top], ":", color="grey", label="striking velocity")
        axv.set_xlim(0, vmax * 1.1)
        axv.set_ylim(0, top)
    axv.set_xlabel("striking velocity (m/s)")
    axv.set_ylabel("speed (m/s)")
    axv.set_title("fastest debris")
    axv.legend(fontsize=8, loc="upper left")
    axv.grid(alpha=0.3)


def sweep(csv_path, png, tests):
    with open(csv_path) as f:
        rows = [r for r in csv.DictReader(f) if r["residual_velocity"] not in ("", "None")]
    vs = [float(r["striking_velocity"]) for r in rows]
    vr = [float(r["residual_velocity"]) for r in rows]
    a, p, vbl, rms = recht_ipson(vs, vr)
    print(f"Recht-Ipson fit of {csv_path}: a = {a:.3f}, p = {p:.2f}, ballistic limit {vbl:.0f} m/s, rms {rms:.1f} m/s")
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, (ax, axm, axv) = plt.subplots(1, 3, figsize=(16, 4.5))
    debris_panels(axm, axv, rows)
    xs = [vbl + (max(vs) * 1.05 - vbl) * i / 200 for i in range(201)]
    ax.plot([0, vbl] + xs, [0, 0] + [a * (x ** p - vbl ** p) ** (1 / p) for x in xs], "-", color="tab:blue",
            label=f"Recht-Ipson fit: $v_{{bl}}$ = {vbl:.0f} m/s, a = {a:.2f}, p = {p:.2f}")
    ax.plot(vs, vr, "o", color="tab:blue", label="shard (K&C, f'c = 48 MPa)")
    if tests:
        with open(tests) as f:
            t = [r for r in csv.DictReader(f)]
        ax.plot([float(r["striking_velocity"]) for r in t], [float(r["residual_velocity"]) for r in t], "s",
                mfc="none", color="k", label=t[0].get("source", "tests"))
    else:
        ax.text(0.98, 0.02, "test points not drawn: the paper's table was not reachable", transform=ax.transAxes,
                ha="right", va="bottom", fontsize=7, color="grey")
    ax.plot([0, 1200], [0, 1200], ":", color="grey", lw=0.8)
    ax.set_xlim(0, max(vs) * 1.1)
    ax.set_ylim(0, max(vs) * 1.05)
    ax.set_xlabel("striking velocity (m/s)")
    ax.set_ylabel("residual velocity (m/s)")
    ax.set_title("Hanchak et al. (1992) slab, 178 mm, 48 MPa")
    ax.legend(fontsize=8, loc="upper left")
    ax.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(png, dpi=130)
    return {"a": a, "p": p, "ballistic_limit": vbl, "rms": rms}



def forrestal_force(depth, v, fc=FC, rho=RHO, a=RADIUS, psi=CRH, von_mises=None):
    """Resisting force (N) of the cavity-expansion model at tip depth (m) and speed (m/s): the
    empirical concrete model, or with von_mises = (Y, E, nu) the elastic-perfectly plastic one."""
    n = (8 * psi - 1) / (24 * psi ** 2)
    if von_mises:
        y, e, nu = von_mises
        static, dynamic = 2 / 3 * y * (1 + math.log(e / (3 * (1 - nu) * y))), 1.5 * n * rho * v * v
    else:
        static, dynamic = 82.6 * (fc / 1e6) ** -0.544 * fc, n * rho * v * v
    tunnel = math.pi * a * a * (static + dynamic)
    return tunnel * min(depth / (2 * a), 1.0) if 0 < depth <= -REAR else 0.0


def resisting_force(out_dir, window=None):
    """[(tip depth, speed, force)] of one run: -m dv/dt over windows of `window` tip travel (the
    run's particle spacing by default)."""
    window = window or spacing_of(out_dir)
    rows = history(out_dir)
    t = [float(r["time"]) for r in rows]
    v = [-float(r["v_projectile"]) for r in rows]
    depth = [-float(r["tip_z"]) for r in rows]
    out, j = [], 0
    for i in range(1, len(rows)):
        if depth[i] - depth[j] >= window and t[i] > t[j]:
            out.append((0.5 * (depth[i] + depth[j]), 0.5 * (v[i] + v[j]), MASS * (v[j] - v[i]) / (t[i] - t[j])))
            j = i
    return out


def tunnel_mean(f, **estimate):
    """(mean force, mean estimate) over the windows of f with the tip 2 a to 100 mm deep; None if
    there are none. `estimate` goes to forrestal_force (fc, rho, von_mises)."""
    tun = [(d, v, x) for d, v, x in f if 2 * RADIUS <= d <= 0.1]
    if not tun:
        return None
    return (sum(x for _, _, x in tun) / len(tun), sum(forrestal_force(d, v, **estimate) for d, v, _ in tun) / len(tun))


def force(png, runs, von_mises=None):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, ax = plt.subplots(figsize=(6.5, 4.5))
    result = {}
    for k, spec in enumerate(runs):
        out_dir, _, label = spec.partition("=")
        label = label or os.path.basename(os.path.normpath(out_dir))
        f = resisting_force(out_dir)
        if not f:
            print(f"{label:30s} the tip has not travelled one window ({spacing_of(out_dir) * 1e3:.0f} mm)")
            continue
        color = f"C{k}"
        est = estimate_parameters(out_dir, von_mises)
        ax.plot([d * 1e3 for d, _, _ in f], [x / 1e3 for _, _, x in f], "-", color=color, label=label)
        ax.plot([d * 1e3 for d, _, _ in f], [forrestal_force(d, v, **est) / 1e3 for d, v, _ in f], ":", color=color)
        print(f"{label:30s} deepest tip {max(d for d, _, _ in f) * 1e3:.0f} mm, force there {f[-1][2] / 1e3:.1f} kN, "
              f"estimate {forrestal_force(f[-1][0], f[-1][1], **est) / 1e3:.1f} kN")
        # The mean over the tunnel region (2 a to 100 mm deep) against the estimate there.
        tun = tunnel_force(out_dir, f, von_mises)
        if tun["tunnel_force"] is not None:
            result[label] = tun
            print(f"{label:30s} mean force 25-100 mm deep {tun['tunnel_force'] / 1e3:7.1f} kN, estimate "
                  f"{tun['tunnel_force_estimate'] / 1e3:7.1f} kN, ratio {tun['tunnel_force_ratio']:.2f}")
        else:
            print(f"{label:30s} tip not yet {2 * RADIUS * 1e3:.0f} mm deep")
    ax.axvline(REAR * -1e3, color="grey", lw=0.8)
    ax.set_xlabel("tip depth (mm)")
    ax.set_ylabel("resisting force (kN)")
    ax.set_xlim(0, None)
    ax.set_title("Projectile force: shard (solid), cavity-expansion estimate (dotted)", fontsize=9)
    ax.legend(fontsize=8)
    ax.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(png, dpi=130)
    return result


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = ap.add_subparsers(dest="cmd", required=True)
    r = sub.add_parser("run")
    r.add_argument("out_dir")
    r.add_argument("--json")
    s = sub.add_parser("sweep")
    s.add_argument("csv")
    s.add_argument("png")
    s.add_argument("--tests", help="CSV of test points (striking_velocity, residual_velocity, source)")
    s.add_argument("--json")
    g = sub.add_parser("force")
    g.add_argument("png")
    g.add_argument("runs", nargs="+", help="OUTPUT_DIR or OUTPUT_DIR=LABEL")
    g.add_argument("--json")
    g.add_argument("--von-mises", help="Y,E,NU of an elastic-perfectly plastic target (Pa, Pa, 1)")
    args = ap.parse_args()
    res = (run_report(args.out_dir) if args.cmd == "run" else
           sweep(args.csv, args.png, args.tests) if args.cmd == "sweep" else
           force(args.png, args.runs, [float(x) for x in args.von_mises.split(",")] if args.von_mises else None))
    if args.cmd == "run":
        for k, v in res.items():
            print(f"  {k:24s} {v}")
    if args.json:
        with open(args.json, "w") as f:
            json.dump(res, f, indent=1)


if __name__ == "__main__":
    main()
