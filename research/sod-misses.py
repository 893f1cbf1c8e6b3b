#!/usr/bin/env python3
"""How K chosen by SOD compares with the true K, per cross-validation run.

Usage: research/sod-misses.py docs/results/<run> [...]
Each run directory holds kept-eval.json (ensembles of kept fold models) or summary.json, whose
rows have k_true and sod.k. Prints, per run, the folds whose K was right, too low and too high,
then the folds picked too low, with their true and chosen K and the share of the clip's points
outside its two largest motions (read from $MULTIFIT_DATA/kt3dmoseg_first5, default
../shared/datasets). For rows that hold residual curves, also how tight the clusters are at the
true K (see tightness).
"""
import collections
import json
import math
import os
import sys


def rows(run):
    """The per-fold rows of a run: kept-eval.json for ensembles of kept fold models, else summary.json."""
    kept = os.path.join(run, "kept-eval.json")
    return json.load(open(kept if os.path.exists(kept) else os.path.join(run, "summary.json")))["rows"]


def beyond_two(name):
    """Share of the test clip's points outside its two largest groups, or None without the data."""
    data = os.environ.get("MULTIFIT_DATA", "../shared/datasets")
    path = os.path.join(data, "kt3dmoseg_first5", name.split("[")[0] + ".json")
    if not os.path.exists(path):
        return None
    sizes = sorted(collections.Counter(json.load(open(path))["labels"]).values(), reverse=True)
    return sum(sizes[2:]) / sum(sizes)


def tightness(rs):
    """How tight the clusters are at the true K, from the residual curves (rows that hold them):
    the mean of r(K_true) / n over the folds, the mean log drop log(r(K_true - 1) / r(K_true)) over
    the folds with 3 or more motions, and their count. SOD picks K_true only where that drop
    stands out against the drop of the first split. None for rows without residual curves."""
    if not all("residuals" in r for r in rs):
        return None
    spread = [r["residuals"][r["k_true"] - 1] / r["n"] for r in rs]
    drops = [math.log(r["residuals"][r["k_true"] - 2] / r["residuals"][r["k_true"] - 1])
             for r in rs if r["k_true"] > 2]
    return sum(spread) / len(spread), sum(drops) / max(len(drops), 1), len(drops)


def main(runs):
    if not runs:
        sys.exit(__doc__)
    for run in runs:
        rs = rows(run)
        if not rs:
            print(f"{os.path.basename(run)}: no per-fold rows")
            continue
        right = sum(r["sod"]["k"] == r["k_true"] for r in rs)
        low = [r for r in rs if r["sod"]["k"] < r["k_true"]]
        high = sum(r["sod"]["k"] > r["k_true"] for r in rs)
        print(f"{os.path.basename(run)}: {len(rs)} folds, right {right}, too low {len(low)}, too high {high}")
        tight = tightness(rs)
        if tight:
            print(f"    mean r(K_true)/n {tight[0]:.4f}; mean log(r(K_true-1)/r(K_true)) over {tight[2]} folds of 3+ motions {tight[1]:.2f}")
        for r in low:
            share = beyond_two(r["name"])
            rest = "" if share is None else f", {100 * share:.1f} % of points beyond the two largest motions"
            print(f"    {r['name']}: true {r['k_true']}, SOD {r['sod']['k']}{rest}")


if __name__ == "__main__":
    main(sys.argv[1:])
