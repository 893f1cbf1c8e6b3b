#!/usr/bin/env python3
"""How ambiguous a set of labelled 2D samples is locally: the leave-one-out k-nearest-neighbour
error with the TRUE labels of all other points (majority vote of a point's k nearest other
points). A point whose neighbours mostly belong to another structure sits where curves cross or
crowd; no purely local method labels it right, only reasoning about whole curves can.

    python3 research/lce-difficulty.py runs/data/lce-test [--k 1 5 10]

Needs numpy. Reads the JSON samples written by `multifit-train gen-lce`.
"""

import argparse
import json
from pathlib import Path

import numpy as np


def knn_error(points: np.ndarray, labels: np.ndarray, k: int) -> float:
    d = ((points[:, None, :] - points[None, :, :]) ** 2).sum(-1)
    np.fill_diagonal(d, np.inf)
    nearest = np.argsort(d, axis=1, kind="stable")[:, :k]
    votes = labels[nearest]
    width = labels.max() + 1
    pred = np.array([np.bincount(row, minlength=width).argmax() for row in votes])
    return float((pred != labels).mean())


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("data", type=Path, help="directory of sample JSON files")
    ap.add_argument("--k", type=int, nargs="+", default=[1, 5, 10])
    a = ap.parse_args()
    files = sorted(a.data.glob("*.json"))
    if not files:
        raise SystemExit(f"{a.data}: no .json samples")
    errors = {k: [] for k in a.k}
    for f in files:
        s = json.loads(f.read_text())
        p = np.asarray(s["points"], dtype=float)
        l = np.asarray(s["labels"], dtype=int)
        for k in a.k:
            errors[k].append(knn_error(p, l, k))
    print(f"{a.data}: {len(files)} samples")
    for k, e in errors.items():
        print(f"leave-one-out {k}-NN error with true labels: {100 * np.mean(e):.2f} %")


if __name__ == "__main__":
    main()
