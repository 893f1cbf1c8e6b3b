#!/usr/bin/env python3
"""How well any method could tell gross outliers from curve points in LCE sets: each true curve
fitted on its own true points (total least squares for the line, taken whole as the server's
line model is; Fitzgibbon's direct fit for the conics), then every point's distance to the
nearest fitted curve. A point is called an outlier
when that distance exceeds t x sigma (sigma: the generator's noise, `--noise`); the precision and
recall of those calls, for several t, bound what a fit with the true models and a threshold
could reach. Uniform outliers that fall inside a curve's band are indistinguishable from its
points.

    ./target/release/multifit-train gen-lce --out runs/data/lce-o20 --count 100 --seed 1000 \
        --scale 2 --outliers 0.2
    python3 research/outlier-ceiling.py runs/data/lce-o20 [--noise 0.05]

Needs numpy. Reads the generator's file format (outliers labelled 0, the curve types in
`source`).
"""
import argparse
import glob
import json

import numpy as np


def distance_to_curve(pts, kind):
    """The curve of `kind` fitted on `pts` [n, 2], as a function of points [m, 2] -> their
    distances to it [m]."""
    if kind == "Line":
        c = pts.mean(0)
        normal = np.linalg.svd(pts - c)[2][1]
        # The infinite line, as the server's line model: no segment ends.
        return lambda q: np.abs((q - c) @ normal)
    x, y = pts[:, 0], pts[:, 1]
    design = np.stack([x * x, x * y, y * y, x, y, np.ones_like(x)], 1)
    scatter = design.T @ design
    constraint = np.zeros((6, 6))
    constraint[0, 2] = constraint[2, 0] = 2
    constraint[1, 1] = -1
    w, v = np.linalg.eig(np.linalg.solve(scatter, constraint))
    a, b, c, d, e, f = np.real(v[:, np.argmax(np.real(w))])
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
        kinds = d["source"].split("shapes [")[1].split("]")[0].split(", ")
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
