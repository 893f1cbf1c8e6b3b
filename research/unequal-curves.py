"""Curves of very unequal density: 2 to 4 curves of random types (line segment, circle, ellipse)
in a 1920 x 1080 image, each with a point count log-uniform in 40..1500 (so one curve often holds
ten times another's points), sizes 100 to 450 px, centres in the middle half of the image (curves
cross and overlap), Gaussian noise of sigma uniform 0.3..1.5 px per set, rows shuffled; with
--outliers F a share F of uniform outliers over the image. Posted with K chosen, or with the true
k (--k): mean error (a curve's point answered -1 counts as wrong, an outlier counts right only
when answered -1), wrong answers (k not the count or over 5 %
error) and how often the smallest curve is found (75 % of its points in one structure that holds
at most 1.25 times its count). Needs a running server.

  python3 research/unequal-curves.py PORT [--k] [--seeds N] [--first-seed S] [--outliers F] [--list]"""
import argparse, math, random

import fitting

ap = argparse.ArgumentParser()
ap.add_argument("port")
ap.add_argument("--k", action="store_true", help="send the true number of curves")
ap.add_argument("--seeds", type=int, default=30)
ap.add_argument("--first-seed", type=int, default=0)
ap.add_argument("--outliers", type=float, default=0.0)
ap.add_argument("--model", default="lce")
ap.add_argument("--list", action="store_true")
args = ap.parse_args()


def one(seed):
    rng = random.Random(seed)
    m = rng.randint(2, 4)
    sigma = rng.uniform(0.3, 1.5)
    rows, truth, kinds = [], [], []
    for label in range(1, m + 1):
        n = round(math.exp(rng.uniform(math.log(40), math.log(1500))))
        kind = rng.choice(["line", "circle", "ellipse"])
        cx, cy = rng.uniform(480, 1440), rng.uniform(270, 810)
        a = rng.uniform(100, 450)
        b = a * rng.uniform(0.3, 0.8) if kind == "ellipse" else a
        th = rng.uniform(0, math.pi)
        for _ in range(n):
            if kind == "line":
                t = rng.uniform(-a, a)
                x, y = cx + t * math.cos(th), cy + t * math.sin(th)
            else:
                u = rng.uniform(0, 2 * math.pi)
                x = cx + a * math.cos(u) * math.cos(th) - b * math.sin(u) * math.sin(th)
                y = cy + a * math.cos(u) * math.sin(th) + b * math.sin(u) * math.cos(th)
            rows.append([x + rng.gauss(0, sigma), y + rng.gauss(0, sigma)])
            truth.append(label)
        kinds.append((kind, n))
    inliers = len(rows)
    for _ in range(round(args.outliers / (1 - args.outliers) * inliers)):
        rows.append([rng.uniform(0, 1920), rng.uniform(0, 1080)])
        truth.append(0)
    order = list(range(len(rows)))
    rng.shuffle(order)
    return [rows[i] for i in order], [truth[i] for i in order], kinds


errors, wrong, found = [], 0, 0
for seed in range(args.first_seed, args.first_seed + args.seeds):
    rows, truth, kinds = one(seed)
    body = {"kind": "points2d", "model": args.model, "points": rows}
    if args.k:
        body["k"] = len(kinds)
    r = fitting.post(args.port, body)
    e = fitting.error_minus_one(truth, r["labels"])
    smallest = 1 + min(range(len(kinds)), key=lambda i: kinds[i][1])
    bad = r["k"] != len(kinds) or e > 0.05
    errors.append(e)
    wrong += bad
    found += fitting.found(truth, r["labels"], smallest)
    if args.list:
        print(seed, kinds, "k", r["k"], "error %.2f" % (100 * e),
              [(s["type"], s["inliers"]) for s in r["structures"]], "WRONG" if bad else "")
print(f"{'k given' if args.k else 'K chosen'}: mean error {100 * sum(errors) / len(errors):.2f} %, "
      f"wrong {wrong}/{len(errors)}, the smallest curve found {found}/{len(errors)}")
