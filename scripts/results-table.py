#!/usr/bin/env python3
"""Prints a Markdown table of evaluation results from their JSON files.

Usage: scripts/results-table.py [DIR]   (default runs/cv; `docs/results` re-reads every
figure of docs/RESULTS.md from the files kept there)

Every JSON file under DIR with a `totals` object gets one row: a cross-validation run's
summary.json, the kept-eval*.json of scripts/cv-eval-kept.sh and scripts/cv-ensemble.sh, or a
`multifit-train eval --json` output. Per-fold files (under folds/) are skipped. Columns: mean /
median error with known K and its NMI, with SOD's K and with the silhouette's K (in %), the
share of samples whose K was chosen right, and the total training time of all folds where the
file records it.
"""
import json
import pathlib
import sys

root = pathlib.Path(sys.argv[1] if len(sys.argv) > 1 else "runs/cv")
print("| file | samples | known K mean / median (NMI) | SOD mean / median (K right) "
      "| silhouette mean / median (K right) | training, all folds |")
print("|---|---|---|---|---|---|")
for path in sorted(root.rglob("*.json")):
    if "folds" in path.relative_to(root).parts:
        continue
    try:
        s = json.loads(path.read_text())
    except (OSError, ValueError):
        continue
    if not isinstance(s, dict) or "totals" not in s:
        continue
    t = s["totals"]

    def cell(key, right=True):
        c = t[key]
        text = f"{100 * c['mean_error']:.2f} / {100 * c['median_error']:.2f}"
        if right:
            return text + f" ({100 * c['k_correct']:.1f} %)"
        return text + f" ({c['mean_nmi']:.3f})"

    train = s.get("train_seconds_total")
    train = f"{train / 60:.1f} min" if train else ""
    print(f"| {path.relative_to(root)} | {t['samples']} | {cell('known', False)} | {cell('sod')} "
          f"| {cell('silhouette')} | {train} |")
