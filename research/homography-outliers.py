"""Two or three homographies with gross outliers, posted with k given and with K chosen: the
error, the answer's k, the structures' RMS and how many of the true outliers are answered -1.
Needs a running server.

  python3 research/homography-outliers.py PORT [--seeds N] [--planes P] [--outliers R] [--list]

Each plane's points are drawn in its own region of a 640 x 480 image (a random rectangle inside
one of P vertical strips: a plane is seen as one patch, and one pixel sees one surface), mapped
by a homography near a small camera motion, with 1 px noise in both images; outliers are uniform
over both images, R times the inliers (default 0.25). --whole draws every plane over the whole
first image instead, which no single camera sees. The structures' RMS is printed with --list."""
import argparse, random

import fitting
from fitting import error

ap = argparse.ArgumentParser()
ap.add_argument("port")
ap.add_argument("--seeds", type=int, default=15)
ap.add_argument("--planes", type=int, default=2)
ap.add_argument("--per-plane", type=int, default=120)
ap.add_argument("--outliers", type=float, default=0.25)
ap.add_argument("--noise", type=float, default=1.0)
ap.add_argument("--model", default="adelaide-homography")
ap.add_argument("--list", action="store_true")
ap.add_argument("--whole", action="store_true", help="every plane over the whole first image")
args = ap.parse_args()
W, H = 640, 480


def apply(h, x, y):
    u = h[0] * x + h[1] * y + h[2]
    v = h[3] * x + h[4] * y + h[5]
    w = h[6] * x + h[7] * y + h[8]
    return u / w, v / w


def homography(rng):
    """A similarity near the identity with a small projective part, in pixels."""
    import math
    a = rng.uniform(-0.15, 0.15)
    s = rng.uniform(0.9, 1.1)
    tx, ty = rng.uniform(-40, 40), rng.uniform(-40, 40)
    p, q = rng.uniform(-4e-4, 4e-4), rng.uniform(-4e-4, 4e-4)
    c, d = s * math.cos(a), s * math.sin(a)
    # about the image centre
    cx, cy = W / 2, H / 2
    return [c, -d, cx + tx - c * cx + d * cy, d, c, cy + ty - d * cx - c * cy, p, q, 1 - p * cx - q * cy]


def one(seed):
    rng = random.Random(seed)
    rows, labels = [], []
    for j in range(args.planes):
        h = homography(rng)
        strip = W / args.planes
        x0, y0 = j * strip + rng.uniform(0, 0.2) * strip, rng.uniform(0, 0.3) * H
        w, hh = rng.uniform(0.6, 0.8) * strip, rng.uniform(0.5, 0.7) * H
        if args.whole:
            x0, y0, w, hh = 0, 0, W, H
        for _ in range(args.per_plane):
            x, y = rng.uniform(x0, x0 + w), rng.uniform(y0, y0 + hh)
            u, v = apply(h, x, y)
            n = args.noise
            rows.append([x + rng.gauss(0, n), y + rng.gauss(0, n), u + rng.gauss(0, n), v + rng.gauss(0, n)])
            labels.append(j + 1)
    for _ in range(int(args.outliers * len(rows))):
        rows.append([rng.uniform(0, W), rng.uniform(0, H), rng.uniform(0, W), rng.uniform(0, H)])
        labels.append(0)
    order = list(range(len(rows)))
    rng.shuffle(order)
    return [rows[i] for i in order], [labels[i] for i in order]


for mode in ("k given", "K chosen"):
    errs, bad, recall = [], 0, []
    for seed in range(args.seeds):
        rows, truth = one(seed)
        body = {"kind": "correspondences", "model": args.model, "points": rows,
                "image_size": [W, H], "refine": True}
        if mode == "k given":
            body["k"] = args.planes
        r = fitting.post(args.port, body)
        e = error(truth, [max(l, -1) for l in r["labels"]])
        rms = [round(s["rms"], 1) for s in r["structures"]]
        out = [l for l, t in zip(r["labels"], truth) if t == 0]
        rec = sum(1 for l in out if l == -1) / max(1, len(out))
        errs.append(e)
        recall.append(rec)
        wrong = r["k"] != args.planes or e > 0.05
        bad += wrong
        if args.list:
            print(mode, seed, "k", r["k"], "err %.2f" % (100 * e), "rms", rms, "recall %.2f" % rec,
                  "WRONG" if wrong else "")
    print(f"{mode}: mean error {100 * sum(errs) / len(errs):.2f} %, wrong {bad}/{len(errs)}, "
          f"outlier recall {sum(recall) / len(recall):.2f}")
