#!/usr/bin/env python3
# SPDX-License-Identifier: LGPL-2.1-or-later
"""Spall and breach of a slab under blast from what `shard run` wrote (doc/manual/blast.md,
"Concrete slab under close-in blast"):

    blast_slab_report.py OUTPUT_DIR [--rear 0] [--front 0.05] [--spacing 0.005] [--json FILE]
                         [--png FILE]

The slab's thickness runs along z from --rear (the face away from the charge) to --front (the
loaded face); --spacing is the element size (the particle lattice). Reads, at the last field
output: OUTPUT_DIR/fragments.csv (fragments with mass, centre, velocity) and the particles
(particles_NNNN.*.vtu: current position x = X + d, displacement d, velocity v).

Definitions (all at the last field output):
  slab       the heaviest fragment (it holds the FE far field and the clamped edges);
  debris     every other fragment; detached mass = their mass;
  spall      debris whose centre lies in the rear half of the slab or behind it (z < mid-plane)
             and which moves away from the charge (vz < 0): spalled mass, its mass-weighted mean
             and largest rearward speed, its kinetic energy; 'behind the rear face' is the part
             whose centre has already passed z = rear;
  detached particle  a particle that is a one-particle fragment (a free particle: all bonds
             broken), matched by its current position to the fragment centre. Debris pieces of
             several particles are not mapped to particles (their particles count as attached),
             so the crater and breach sizes below are lower bounds; the count of such pieces is
             printed;
  column     the particles with the same reference (x, y) lattice position (h / spacing + 1
             of them through the thickness where the slab is particles);
  rear crater  the columns whose rear-face particle is detached: area n s^2 and the diameter
             of the circle of that area; front crater likewise on the loaded face;
  breach     a column in which every particle through the thickness is detached: a hole
             through the slab. Breach area n s^2, equivalent diameter; breached = n > 0.
Classification: 'breach' if a column is open, else 'spall' if the rear crater is not empty (and
spalled mass > 0; 'incipient spall' without it), else 'front crater only' if there is debris,
else 'no debris' (bonds may still have broken: see broken_bonds in summary.json).
"""
import argparse
import json
import math
import os
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from shard_output import last_fragments, last_pieces, read_vtu  # noqa: E402


def last_particles(out_dir):
    """(x, d, v, volume) of every particle of the last particle output, all ranks."""
    particles = []
    for piece in last_pieces(out_dir, "particles"):
        a = {k: [v[i:i + c] for i in range(0, len(v), c)] if c > 1 else v for k, (v, c) in read_vtu(piece).items()}
        for x, d, v, vol in zip(a["Points"], a["displacement"], a["velocity"], a["volume"]):
            particles.append((x, d, v, vol))
    return particles


def plot(args, res, columns, section, n_layers):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    s = args.spacing
    fig, (a, b) = plt.subplots(1, 2, figsize=(12, 4.2), gridspec_kw={"width_ratios": [1.6, 1]})
    for det, colour, label in ((False, "0.6", "attached particles"), (True, "tab:red", "free particles (debris)")):
        pts = [(x, z) for x, z, d in section if d == det]
        if pts:
            a.scatter([p[0] * 1e3 for p in pts], [p[1] * 1e3 for p in pts], s=6, c=colour, label=label)
    a.axhline(args.rear * 1e3, color="k", lw=0.5)
    a.axhline(args.front * 1e3, color="k", lw=0.5)
    a.set_aspect("equal")
    a.set_xlabel("x (mm)")
    a.set_ylabel("z (mm), rear face z = %g" % (args.rear * 1e3))
    a.set_title("section y = 0 at %.0f us (particle region; the rest is FE)" % (res["time"] * 1e6))
    a.legend(loc="upper right", fontsize=8)
    for ij, c in columns.items():
        if len(c) == n_layers and all(c.values()):
            colour = "tab:red"
        elif c.get(0, False):
            colour = "tab:orange"
        elif c.get(n_layers - 1, False):
            colour = "tab:blue"
        else:
            colour = "0.85"
        b.add_patch(plt.Rectangle(((ij[0] - 0.5) * s * 1e3, (ij[1] - 0.5) * s * 1e3), s * 1e3, s * 1e3,
                                  color=colour, lw=0))
    ext = max(max(abs(i), abs(j)) for i, j in columns) * s * 1e3 + s * 1e3
    b.set_xlim(-ext, ext)
    b.set_ylim(-ext, ext)
    b.set_aspect("equal")
    b.set_xlabel("x (mm)")
    b.set_ylabel("y (mm)")
    b.set_title("columns: red breach, orange rear crater,\nblue front crater only, grey intact", fontsize=9)
    fig.suptitle("%s: spalled %.0f g, rear crater %.0f mm, breach %.0f mm (equivalent diameters)"
                 % (res["verdict"], res["spalled_mass"] * 1e3, res["rear_crater_diameter"] * 1e3,
                    res["breach_diameter"] * 1e3), fontsize=10)
    fig.tight_layout()
    fig.savefig(args.png, dpi=110)


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("out_dir")
    ap.add_argument("--rear", type=float, default=0.0)
    ap.add_argument("--front", type=float, default=0.05)
    ap.add_argument("--spacing", type=float, default=0.005)
    ap.add_argument("--json", help="also write the numbers to this file")
    ap.add_argument("--png", help="also draw the section y = 0 and the rear-face map (needs matplotlib)")
    args = ap.parse_args()
    h, s = args.front - args.rear, args.spacing
    mid = 0.5 * (args.rear + args.front)

    path = os.path.join(args.out_dir, "fragments.csv")
    t, frags = last_fragments(path)
    if not frags:
        raise SystemExit(f"{path}: no fragments")
    total = sum(float(r["mass"]) for r in frags)
    slab = max(frags, key=lambda r: float(r["mass"]))
    debris = [r for r in frags if r is not slab]
    spall = [r for r in debris if float(r["z"]) < mid and float(r["vz"]) < 0]
    behind = [r for r in spall if float(r["z"]) < args.rear]
    m_spall = sum(float(r["mass"]) for r in spall)
    v_mean = (sum(float(r["mass"]) * -float(r["vz"]) for r in spall) / m_spall) if m_spall > 0 else 0.0
    v_max = max([-float(r["vz"]) for r in spall] + [0.0])
    ke_spall = sum(float(r["kinetic_energy"]) for r in spall)
    multi = [r for r in debris if int(float(r["particles"])) > 1 or int(float(r["nodes"])) > 1]

    # Free particles: one-particle fragments, matched by their current position.
    # (positions to 1e-4 of the spacing: the two files round differently; neighbouring keys
    # are searched too)
    q = 1e-4 * s
    free = {}
    for r in debris:
        if int(float(r["particles"])) == 1 and int(float(r["nodes"])) == 1:
            key = tuple(round(float(r[c]) / q) for c in ("x", "y", "z"))
            free[key] = r
    near = [(a, b, c) for a in (-1, 0, 1) for b in (-1, 0, 1) for c in (-1, 0, 1)]
    columns = {}
    section = []
    n_matched = 0
    for x, d, v, vol in last_particles(args.out_dir):
        X = [x[i] - d[i] for i in range(3)]
        key = tuple(round(x[i] / q) for i in range(3))
        detached = any((key[0] + a, key[1] + b, key[2] + c) in free for a, b, c in near)
        n_matched += detached
        ij = (round(X[0] / s), round(X[1] / s))
        k = round((X[2] - args.rear) / s)
        columns.setdefault(ij, {})[k] = detached
        if args.png and abs(X[1]) < 0.5 * s:
            section.append((x[0], x[2], detached))
    n_layers = round(h / s) + 1
    rear = [c for c in columns.values() if c.get(0, False)]
    front = [c for c in columns.values() if c.get(n_layers - 1, False)]
    open_ = [c for c in columns.values() if len(c) == n_layers and all(c.values())]
    # Deepest rear-face spall: detached layers counted from the rear face, per column.
    depth = 0
    for c in columns.values():
        k = 0
        while c.get(k, False):
            k += 1
        depth = max(depth, k)

    def diameter(n):
        return 2 * math.sqrt(n * s * s / math.pi)

    if open_:
        verdict = "breach"
    elif rear:
        verdict = "spall" if m_spall > 0 else "incipient spall (rear-face particles detached, not moving away)"
    elif debris:
        verdict = "front crater only"
    else:
        verdict = "no debris"
    res = {
        "time": t, "total_mass": total, "n_fragments": len(frags), "slab_mass": float(slab["mass"]),
        "detached_mass": total - float(slab["mass"]), "n_debris_pieces_of_several_particles": len(multi),
        "spalled_mass": m_spall, "spall_fragments": len(spall), "spall_mean_rear_speed": v_mean,
        "spall_max_rear_speed": v_max, "spall_kinetic_energy": ke_spall,
        "mass_behind_rear_face": sum(float(r["mass"]) for r in behind),
        "free_particles_matched": n_matched, "free_particles": len(free),
        "rear_crater_diameter": diameter(len(rear)), "front_crater_diameter": diameter(len(front)),
        "rear_spall_depth": min(depth * s, h), "breach_columns": len(open_), "breach_diameter": diameter(len(open_)),
        "breached": bool(open_), "verdict": verdict,
    }
    print(f"blast slab report: {args.out_dir} at t = {t * 1e6:.1f} us")
    print(f"  fragments              {len(frags)} (slab {float(slab['mass']):.4f} kg of {total:.4f} kg; "
          f"{len(multi)} debris pieces of several particles)")
    print(f"  detached mass          {res['detached_mass'] * 1e3:.2f} g")
    print(f"  spalled mass (rear)    {m_spall * 1e3:.2f} g in {len(spall)} fragments, rearward speed "
          f"{v_mean:.1f} m/s mass-weighted mean, {v_max:.1f} m/s largest, kinetic energy {ke_spall:.2f} J; "
          f"{res['mass_behind_rear_face'] * 1e3:.2f} g already behind the rear face")
    print(f"  rear crater            {len(rear)} columns, equivalent diameter {res['rear_crater_diameter'] * 1e3:.0f} mm, "
          f"deepest {res['rear_spall_depth'] * 1e3:.0f} mm of {h * 1e3:.0f} mm")
    print(f"  front crater           {len(front)} columns, equivalent diameter {res['front_crater_diameter'] * 1e3:.0f} mm")
    print(f"  breach                 {len(open_)} open columns, equivalent diameter {res['breach_diameter'] * 1e3:.0f} mm")
    print(f"  verdict                {verdict}")
    if n_matched != len(free):
        print(f"  note: {len(free) - n_matched} free particles not matched to the particle output", file=sys.stderr)
    if args.png:
        plot(args, res, columns, section, n_layers)
    if args.json:
        with open(args.json, "w") as f:
            json.dump(res, f, indent=1)


if __name__ == "__main__":
    main()
