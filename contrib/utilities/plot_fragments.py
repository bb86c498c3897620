#!/usr/bin/env python3
# SPDX-License-Identifier: LGPL-2.1-or-later
"""Plot the fragment statistics of a run: plot_fragments.py OUTPUT_DIR [PNG].

Reads OUTPUT_DIR/fragment_statistics.csv (written by `shard run` when the scene has particles)
and writes PNG (default OUTPUT_DIR/fragments.png) with three panels about the debris (every
fragment but the heaviest of each body; doc/manual/failure.md, "Fragments"):
  left:   cumulative fraction of the debris mass against the fragment mass, the debris that is
          not dust first (largest first, so the curve reads "fraction of the debris mass in
          fragments at least this heavy"), then the dust (debris of fewer than `K - Output/dust
          particles` nodes) in its own colour over the shaded band of its mass fraction;
  middle: mass-weighted distribution of the debris speeds, dust stacked apart; the speeds of
          the bodies (the heaviest fragment of each) as dotted lines;
  right:  mass-weighted distribution of the debris cone angles (between the velocity and
          `K - Output/debris axis`), dust stacked apart, with the 90 % angle.
An older fragment_statistics.csv without the debris columns is read with every fragment but
the heaviest as debris and no dust.
"""
import csv
import os
import re
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

COARSE, DUST = "tab:blue", "tab:orange"


def parameter(out_dir, path):
    """The value of the key 'A/B/key' in the run's parameters.prm (None if absent)."""
    prm = os.path.join(out_dir, "parameters.prm")
    if not os.path.exists(prm):
        return None
    stack = []
    with open(prm) as f:
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


def weighted_quantile(values, weights, q):
    """The smallest value v with at least the fraction q of the weight at values <= v."""
    pairs = sorted(zip(values, weights))
    total, running = sum(weights), 0.0
    for v, w in pairs:
        running += w
        if running >= q * total * (1 - 1e-12):
            return v
    return pairs[-1][0] if pairs else 0.0


def main():
    if len(sys.argv) < 2:
        raise SystemExit(__doc__)
    out_dir = sys.argv[1]
    png = sys.argv[2] if len(sys.argv) > 2 else os.path.join(out_dir, "fragments.png")
    with open(os.path.join(out_dir, "fragment_statistics.csv")) as f:
        rows = list(csv.DictReader(f))
    if not rows:
        raise SystemExit("no fragments in fragment_statistics.csv")
    classified = "debris" in rows[0]
    for k, r in enumerate(rows):
        r["mass"] = float(r["mass"])
        r["speed"] = float(r["speed"])
        r["debris"] = int(r["debris"]) if classified else int(k > 0)
        r["dust"] = int(r["dust"]) if classified else 0
        r["cone_angle"] = float(r["cone_angle"]) if classified else float("nan")
    time = float(rows[0]["time"])
    total = sum(r["mass"] for r in rows)
    debris = sorted((r for r in rows if r["debris"]), key=lambda r: -r["mass"])
    coarse = [r for r in debris if not r["dust"]]
    dust = [r for r in debris if r["dust"]]
    bodies = [r for r in rows if not r["debris"]]
    m_debris = sum(r["mass"] for r in debris)
    m_dust = sum(r["mass"] for r in dust)
    n_dust = parameter(out_dir, "K - Output/dust particles")
    dust_rule = f"< {n_dust} nodes" if n_dust else "dust"
    axis = parameter(out_dir, "K - Output/debris axis") or "debris axis"

    fig, (a, b, c) = plt.subplots(1, 3, figsize=(15, 4.2))
    # Left: cumulative debris mass fraction of the debris that is not dust, then the dust band.
    if m_debris > 0:
        running, xs, ys = 0.0, [], []
        for r in coarse:
            running += r["mass"]
            xs.append(r["mass"] * 1e3)
            ys.append(running / m_debris)
        if xs:
            a.step(xs, ys, where="post", marker="o", ms=3, color=COARSE,
                   label=f"debris, {len(coarse)} fragments")
        end = 1 - m_dust / m_debris
        if dust:
            a.axhspan(end, 1, color=DUST, alpha=0.2, lw=0)
            running, xs, ys = end * m_debris, [], []
            for r in sorted(dust, key=lambda r: -r["mass"]):
                running += r["mass"]
                xs.append(r["mass"] * 1e3)
                ys.append(running / m_debris)
            a.step(xs, ys, where="post", marker="o", ms=3, color=DUST,
                   label=f"dust ({dust_rule}): {len(dust)} fragments, {100 * m_dust / m_debris:.3g} %")
        a.set_xscale("log")
        a.set_ylim(0, 1.05)
        a.legend(loc="lower right", fontsize=8)
    else:
        a.text(0.5, 0.5, "no debris", ha="center", va="center", transform=a.transAxes)
    a.set_xlabel("debris fragment mass (g)")
    a.set_ylabel("cumulative fraction of the debris mass (largest first)")
    a.grid(True, which="both", alpha=0.3)
    a.set_title(f"debris {m_debris * 1e3:.4g} g of {total * 1e3:.4g} g ({len(rows)} fragments)", fontsize=10)

    # Middle and right: mass-weighted histograms of the debris, dust stacked on the rest.
    def stacked(ax, key, bins, label):
        groups = [g for g in (coarse, dust) if g]
        if not groups:
            ax.text(0.5, 0.5, "no debris", ha="center", va="center", transform=ax.transAxes)
            return
        ax.hist([[r[key] for r in g] for g in groups], bins=bins, stacked=True,
                weights=[[r["mass"] / m_debris for r in g] for g in groups],
                color=[COARSE if g is coarse else DUST for g in groups],
                label=["debris" if g is coarse else f"dust ({dust_rule})" for g in groups])
        ax.set_xlabel(label)
        ax.set_ylabel("fraction of the debris mass")
        ax.grid(True, alpha=0.3)

    n_bins = min(30, max(5, len(debris)))
    stacked(b, "speed", n_bins, "fragment speed (m/s)")
    for r, style in zip(bodies, (":", "-.", "--")):
        b.axvline(r["speed"], color="k", ls=style, lw=1, label=f"body {r.get('body', '')} {r['speed']:.4g} m/s")
    if debris or bodies:
        b.legend(fontsize=8)
    b.set_title(f"speeds at t = {time:.4g} s", fontsize=10)
    if classified:
        stacked(c, "cone_angle", [5 * k for k in range(37)], "cone angle (degrees)")
        if debris:
            c90 = weighted_quantile([r["cone_angle"] for r in debris], [r["mass"] for r in debris], 0.9)
            c.axvline(c90, color="k", ls="--", lw=1, label=f"90 % of the debris mass within {c90:.3g} deg")
            c.legend(fontsize=8)
        c.set_xlim(0, 180)
        c.set_title(f"angle between velocity and axis ({axis})", fontsize=10)
    else:
        c.text(0.5, 0.5, "no cone angles in this file", ha="center", va="center", transform=c.transAxes)
    fig.tight_layout()
    fig.savefig(png, dpi=120)
    print(png)


if __name__ == "__main__":
    main()
