#!/usr/bin/python3
# SPDX-License-Identifier: LGPL-2.1-or-later
"""Plot the history.csv of one or more `shard material-test` runs into one PNG with two panels:

(a) axial stress against axial strain, compression positive for compression paths (the sign is
    taken from the run: negative extreme axial strain = compression); for a hydrostatic run
    pressure against volumetric strain -ln J;
(b) the path in the meridian plane: von Mises stress q against pressure p = -tr(sigma)/3
    (compression positive).

Usage: plot_material_test.py OUT.png CSV [CSV ...] [--labels a,b,...] [--title T]

The path of a run is read from summary.json beside its CSV when there is one; otherwise a run
whose three normal strains are equal in every row counts as hydrostatic. Default labels:
"material (path)" from summary.json, else the name of the CSV's directory.
"""
import argparse
import csv
import json
import os
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402


def read_history(path):
    with open(path) as f:
        rows = list(csv.DictReader(f))
    if not rows:
        raise SystemExit(f"{path}: no rows")
    need = ["strain_xx", "strain_yy", "strain_zz", "volumetric_strain", "stress_xx", "pressure", "q"]
    missing = [c for c in need if c not in rows[0]]
    if missing:
        raise SystemExit(f"{path}: not a material-test history (missing {', '.join(missing)})")
    return {c: [float(r[c]) for r in rows] for c in rows[0]}


def read_summary(csv_path):
    path = os.path.join(os.path.dirname(os.path.abspath(csv_path)), "summary.json")
    try:
        with open(path) as f:
            return json.load(f)
    except (OSError, ValueError):
        return {}


def is_hydrostatic(h, summary):
    if "path" in summary:
        return summary["path"] == "hydrostatic"
    scale = max(max(abs(x) for x in h[c]) for c in ("strain_xx", "strain_yy", "strain_zz")) or 1.0
    return all(abs(a - b) <= 1e-9 * scale and abs(a - c) <= 1e-9 * scale
               for a, b, c in zip(h["strain_xx"], h["strain_yy"], h["strain_zz"]))


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("out", help="PNG to write")
    ap.add_argument("csv", nargs="+", help="history.csv of shard material-test")
    ap.add_argument("--labels", help="comma-separated legend labels, one per CSV")
    ap.add_argument("--title", help="figure title")
    args = ap.parse_args()
    labels = args.labels.split(",") if args.labels else []
    if labels and len(labels) != len(args.csv):
        raise SystemExit(f"--labels has {len(labels)} labels for {len(args.csv)} CSV files")

    fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(11, 4.5))
    kinds = set()
    q_top = 0.0  # q axis: at least a tenth of the largest |p|, so round-off in q stays flat
    for k, path in enumerate(args.csv):
        h = read_history(path)
        summary = read_summary(path)
        if labels:
            label = labels[k]
        elif "material" in summary:
            label = f"{summary['material']} ({summary.get('path', '?')})"
        else:
            label = os.path.basename(os.path.dirname(os.path.abspath(path))) or path
        if is_hydrostatic(h, summary):
            kinds.add("hydrostatic")
            x = [-e for e in h["volumetric_strain"]]
            y = [1e-6 * p for p in h["pressure"]]
        else:
            extreme = max(h["strain_xx"], key=abs)
            sign = -1.0 if extreme < 0 else 1.0
            kinds.add("compression" if sign < 0 else "tension")
            x = [sign * e for e in h["strain_xx"]]
            y = [sign * 1e-6 * s for s in h["stress_xx"]]
        line, = ax1.plot(x, y, label=label)
        ax2.plot([1e-6 * p for p in h["pressure"]], [1e-6 * q for q in h["q"]], color=line.get_color(), label=label)
        q_top = max(q_top, 1.05e-6 * max(h["q"]), 0.1e-6 * max(abs(p) for p in h["pressure"]))

    if kinds == {"hydrostatic"}:
        ax1.set_xlabel("volumetric strain -ln J (compression positive)")
        ax1.set_ylabel("pressure p (MPa)")
        ax1.set_title("(a) pressure against volumetric strain")
    elif kinds == {"compression"}:
        ax1.set_xlabel("axial strain -eps_xx (compression positive)")
        ax1.set_ylabel("axial stress -sigma_xx (MPa)")
        ax1.set_title("(a) axial stress against axial strain")
    elif kinds == {"tension"}:
        ax1.set_xlabel("axial strain eps_xx (tension positive)")
        ax1.set_ylabel("axial stress sigma_xx (MPa)")
        ax1.set_title("(a) axial stress against axial strain")
    else:
        ax1.set_xlabel("strain (compression paths: -eps_xx; tension: eps_xx; hydrostatic: -ln J)")
        ax1.set_ylabel("stress (MPa): -sigma_xx, sigma_xx or p")
        ax1.set_title("(a) stress against strain")
    ax2.set_xlabel("pressure p = -tr(sigma)/3 (MPa, compression positive)")
    ax2.set_ylabel("von Mises stress q (MPa)")
    ax2.set_ylim(-0.02 * (q_top or 1.0), q_top or 1.0)
    ax2.set_title("(b) meridian plane")
    for ax in (ax1, ax2):
        ax.grid(alpha=0.3)
        ax.axhline(0, color="gray", lw=0.5)
        ax.axvline(0, color="gray", lw=0.5)
        ax.legend(fontsize=8)
    if args.title:
        fig.suptitle(args.title)
    fig.tight_layout()
    fig.savefig(args.out, dpi=120)
    print("wrote", args.out)


if __name__ == "__main__":
    sys.exit(main())
