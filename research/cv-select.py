#!/usr/bin/env python3
"""Chooses an evaluation setting (test symmetries, say) for each fold of a cross-validation run
without looking at that fold: every fold gets the setting with the lowest mean error on the
other folds, and is scored under it. Prints that leave-one-fold-out figure beside each setting's
own, whose best is chosen on the test folds themselves and so flatters.

Usage: research/cv-select.py [--key known|sod|silhouette] NAME=FILE [NAME=FILE ...]
Each FILE is an evaluation of the same folds (the kept-eval*.json of scripts/cv-eval-kept.sh, or
an `eval --json` output); the first setting wins ties.
"""
import argparse
import json
import statistics as st
import sys

from loo import choose_without


def load(path):
    rows = json.load(open(path))["rows"]
    return {r["name"]: r for r in rows}


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--key", default="known", choices=["known", "sod", "silhouette"])
    ap.add_argument("settings", nargs="+", metavar="NAME=FILE")
    a = ap.parse_args()
    settings = []
    for s in a.settings:
        name, sep, path = s.partition("=")
        if not sep:
            sys.exit(f"expected NAME=FILE, got {s!r}")
        settings.append((name, load(path)))
    folds = sorted(settings[0][1])
    for name, rows in settings:
        if sorted(rows) != folds:
            sys.exit(f"setting {name} does not hold the same folds as {settings[0][0]}")
    err = {name: {f: rows[f][a.key]["error"] for f in folds} for name, rows in settings}
    names = [n for n, _ in settings]

    def right(name, f):
        r = dict(settings)[name][f]
        return r[a.key]["k"] == r["k_true"]

    for n in names:
        e = list(err[n].values())
        k = sum(right(n, f) for f in folds) / len(folds)
        print(f"{n:24s} mean {100 * st.mean(e):6.2f}  median {100 * st.median(e):6.2f}  "
              f"K right {100 * k:5.1f} %")
    picked = choose_without({n: [err[n][f] for f in folds] for n in names}, names)
    chosen = list(zip(folds, picked))
    picks = {n: picked.count(n) for n in dict.fromkeys(picked)}
    e = [err[n][f] for f, n in chosen]
    k = sum(right(n, f) for f, n in chosen) / len(folds)
    print(f"{'chosen without the fold':24s} mean {100 * st.mean(e):6.2f}  median "
          f"{100 * st.median(e):6.2f}  K right {100 * k:5.1f} %  (picks: "
          + ", ".join(f"{n} {c}" for n, c in picks.items()) + ")")


if __name__ == "__main__":
    main()
