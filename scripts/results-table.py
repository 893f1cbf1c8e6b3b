#!/usr/bin/env python3
"""Prints a Markdown table of cross-validation runs from runs/cv/*/summary.json.

Usage: scripts/results-table.py [runs/cv]  -- one row per run directory: mean / median error with
known K, with SOD's K and with the silhouette's K (in %), the share of folds whose K was chosen
right, and the total training time of all folds.
"""
import json
import pathlib
import sys

root = pathlib.Path(sys.argv[1] if len(sys.argv) > 1 else "runs/cv")
print("| run | folds | known K mean / median | SOD mean / median (K right) | silhouette mean / median (K right) | training, all folds |")
print("|---|---|---|---|---|---|")
for summary in sorted(root.glob("*/summary.json")):
    s = json.loads(summary.read_text())
    t = s["totals"]

    def cell(key, right=True):
        c = t[key]
        text = f"{100 * c['mean_error']:.2f} / {100 * c['median_error']:.2f}"
        return text + (f" ({100 * c['k_correct']:.1f} %)" if right else "")

    print(f"| {summary.parent.name} | {t['samples']} | {cell('known', False)} | {cell('sod')} | {cell('silhouette')} "
          f"| {s.get('train_seconds_total', 0) / 60:.1f} min |")
