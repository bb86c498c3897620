#!/usr/bin/env python3
# SPDX-License-Identifier: LGPL-2.1-or-later
"""Short summary of a finished run, printed by contrib/run: run_summary.py OUTPUT_DIR [SECONDS].

Reads OUTPUT_DIR/summary.json (standard library only) and prints status, steps, the residual
velocity of the projectile (scene quantity v_projectile, when the scene defines it), fragments,
converted elements, broken bonds, free particles, energy error, shard's wall time (and the whole
contrib/run's, SECONDS, when given: the script's time up to the summary), the final value of every other scene quantity and the paths
of the result files that exist.
"""
import json
import os
import sys


def main():
    if len(sys.argv) < 2:
        raise SystemExit(__doc__)
    out = sys.argv[1]
    path = os.path.join(out, "summary.json")
    if not os.path.exists(path):
        print(f"contrib/run: no {path}: the run wrote no summary")
        return 1
    with open(path) as f:
        s = json.load(f)
    results = s.get("results", {})
    rows = []

    def row(label, value):
        rows.append((label, value))

    row("scene", s.get("title", s.get("parameter_file", "")))
    row("status", s.get("status", "?") + (f" ({s['message']})" if s.get("message") else ""))
    row("steps, final time", f"{s.get('steps', 0)} steps to t = {1e6 * s.get('final_time', 0):.1f} us")
    size = f"{s.get('n_elements', 0)} hexahedra, {s.get('n_particles', 0)} particles at the end"
    threads = s.get("n_threads", 1)
    row("model", f"{size}, {s.get('n_mpi_ranks', 1)} MPI ranks"
                 + (f" x {threads} threads" if threads > 1 else ""))
    with_particles = s.get("n_particles", 0) > 0 or s.get("n_converted_elements", 0) > 0
    if "v_projectile" in results:
        v = results["v_projectile"]
        v0 = results.get("v_projectile_min", v) if v < 0 else results.get("v_projectile_max", v)
        row("projectile velocity", f"{abs(v0):.1f} m/s striking -> {abs(v):.1f} m/s residual")
    if with_particles and "n_fragments" in s:
        row("fragments", f"{s['n_fragments']} (largest {1e3 * s.get('largest_fragment_mass', 0):.2f} g, "
                         f"total {1e3 * s.get('fragment_mass_total', 0):.2f} g)")
    if with_particles and "n_converted_elements" in s:
        row("converted elements", f"{s['n_converted_elements']} in {s.get('conversion_events', 0)} events "
                                  f"(conversion energy {s.get('conversion_energy', 0):+.3g} J)")
    if with_particles and "broken_bonds" in s:
        row("broken bonds", f"{s['broken_bonds']} ({s.get('free_particles', 0)} free particles)")
    row("energy error", f"{s.get('energy_error', 0):+.2e} at the end, largest |error| "
                        f"{s.get('max_abs_energy_error', 0):.2e}")
    wall = f"{s.get('wall_time_s', 0):.1f} s in shard"
    if len(sys.argv) > 2:
        wall += f", {float(sys.argv[2]):.0f} s for the whole contrib/run (set-up, build check, run, plots)"
    row("wall time", wall)
    for key, value in results.items():
        if key == "v_projectile" or key.endswith("_min") or key.endswith("_max") or not isinstance(value, (int, float)):
            continue
        row(f"{key} (final)", f"{value:.6g}")

    width = max(len(label) for label, _ in rows)
    print("\n== Summary " + "=" * 60)
    for label, value in rows:
        print(f"  {label:<{width}}  {value}")
    print("  results:")
    files = []
    for name, what in (("summary.json", "status, counts, energy error, scene results"),
                       ("history.csv", "one row per history step"),
                       ("solution.pvd", "the fields over time (mesh, particles), for ParaView"),
                       ("particles.pvd", "the particles alone"),
                       ("fragments.csv", "fragments at every field output"),
                       ("fragment_statistics.csv", "fragments at the end, by mass"),
                       ("fragments.png", "fragment mass and speed distributions"),
                       ("showcase.png", "section of the final state, projectile speed, counts")):
        p = os.path.join(out, name)
        if os.path.exists(p):
            files.append((p, what))
    pad = max((len(p) for p, _ in files), default=0)
    for p, what in files:
        print(f"    {p:<{pad}}  {what}")
    return 0 if s.get("status") in ("completed", "max steps reached") else 1


if __name__ == "__main__":
    sys.exit(main())
