#!/usr/bin/env python3
"""How well any method could tell gross outliers from curve points in LCE sets: each true curve
fitted on its own true points (the least-squares fits of `lce-ransac.py`: the line taken whole,
as the server's line model is; the algebraic circle; Fitzgibbon's direct ellipse fit), then
every point's geometric distance to the nearest fitted curve. A point is called an outlier
when that distance exceeds t x sigma (sigma: the generator's noise, `--noise`); the precision and
recall of those calls, for several t, bound what a fit with the true models and a threshold
could reach. Uniform outliers that fall inside a curve's band are indistinguishable from its
points.

    ./target/release/multifit-train gen-lce --out runs/data/lce-o20 --count 100 --seed 1000 \
        --scale 2 --outliers 0.2
    python3 research/outlier-ceiling.py runs/data/lce-o20 [--noise 0.05]

Needs numpy and scipy (through lce-ransac.py). Reads the generator's file format (outliers
labelled 0, the curve types in `source`).
"""
import argparse
import glob
import importlib.util
import json
from pathlib import Path

import numpy as np

# The fits and the shape list of the sequential-RANSAC baseline (research/lce-ransac.py).
_spec = importlib.util.spec_from_file_location("lce_ransac", Path(__file__).with_name("lce-ransac.py"))
lce_ransac = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(lce_ransac)


def distance_to_curve(pts, kind):
    """The curve of `kind` fitted on `pts` [n, 2] (lce-ransac.py's least-squares fits), as a
    function of points [m, 2] -> their geometric distances to it [m]."""
    a, b, c, d, e, f = lce_ransac.MODELS[kind][2](pts)
    if kind == "line":
        # The infinite line, as the server's line model: no segment ends.
        return lambda q: np.abs(d * q[:, 0] + e * q[:, 1] + f)
    m = np.array([[a, b / 2], [b / 2, c]])
    centre = np.linalg.solve(2 * m, -np.array([d, e]))
    level = -(f + centre @ m @ centre + d * centre[0] + e * centre[1])
    values, vectors = np.linalg.eigh(m)
    axes = np.sqrt(level / values)
    th = np.linspace(0, 2 * np.pi, 4000)
    curve = centre + (vectors @ np.stack([axes[0] * np.cos(th), axes[1] * np.sin(th)])).T
    return lambda q: np.array([np.min(np.linalg.norm(curve - p, axis=1)) for p in q])


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("dir")
    ap.add_argument("--noise", type=float, default=0.05)
    args = ap.parse_args()
    inliers, outliers = [], []
    for path in sorted(glob.glob(f"{args.dir}/*.json")):
        d = json.load(open(path))
        pts, labels = np.array(d["points"]), np.array(d["labels"])
        found = lce_ransac.SHAPES.search(d.get("source") or "")
        kinds = [k.strip().lower() for k in found.group(1).split(",")]
        dist = np.min([distance_to_curve(pts[labels == g + 1], k)(pts)
                       for g, k in enumerate(kinds)], axis=0)
        inliers += list(dist[labels > 0])
        outliers += list(dist[labels == 0])
    inliers, outliers = np.array(inliers), np.array(outliers)
    print(f"{len(outliers)} outliers, {len(inliers)} curve points")
    print("| threshold (sigma) | precision | recall |\n|---|---|---|")
    for t in [1.0, 1.5, 2.0, 2.5, 3.0]:
        tp = (outliers > t * args.noise).sum()
        fp = (inliers > t * args.noise).sum()
        print(f"| {t} | {tp / max(tp + fp, 1):.3f} | {tp / len(outliers):.3f} |")


if __name__ == "__main__":
    main()
