"""A sparse curve beside dense ones: a 400-point line through the middle of a 640 x 480 image at a
random angle, a circle of 150 points and one of 20 (radii 60-120 and 40-80 px, centres anywhere
100 px or more from the border), 1 px noise, rows shuffled. Posted with K chosen, or with k = 3
(--k): mean error (the sets hold no outliers, so a point answered -1 counts as wrong), wrong
answers (k not 3 or over 5 % error) and how often the 20-point circle is found (15 of its points
in one structure that holds few other points). Needs a running server.

  python3 research/sparse-curve.py PORT [--k] [--seeds N] [--in-order] [--list]"""
import argparse, collections, math, random

import fitting

ap = argparse.ArgumentParser()
ap.add_argument("port")
ap.add_argument("--k", action="store_true", help="send k = 3")
ap.add_argument("--seeds", type=int, default=20)
ap.add_argument("--in-order", action="store_true", help="rows as drawn: line, large circle, small")
ap.add_argument("--model", default="lce")
ap.add_argument("--list", action="store_true")
args = ap.parse_args()


def one(seed):
    rng = random.Random(seed)
    rows, truth = [], []
    a = rng.uniform(0, math.pi)
    for _ in range(400):
        t = rng.uniform(-300, 300)
        rows.append([320 + t * math.cos(a) + rng.gauss(0, 1), 240 + t * math.sin(a) + rng.gauss(0, 1)])
        truth.append(1)
    for label, n, r in [(2, 150, rng.uniform(60, 120)), (3, 20, rng.uniform(40, 80))]:
        ox, oy = rng.uniform(100, 540), rng.uniform(100, 380)
        for _ in range(n):
            th = rng.uniform(0, 2 * math.pi)
            rows.append([ox + r * math.cos(th) + rng.gauss(0, 1), oy + r * math.sin(th) + rng.gauss(0, 1)])
            truth.append(label)
    order = list(range(len(rows)))
    if not args.in_order:
        rng.shuffle(order)
    return [rows[i] for i in order], [truth[i] for i in order]


errors, wrong, found = [], 0, 0
for seed in range(args.seeds):
    rows, truth = one(seed)
    body = {"kind": "points2d", "model": args.model, "points": rows}
    if args.k:
        body["k"] = 3
    r = fitting.post(args.port, body)
    # Each point answered -1 in a group of its own: no structure to match, so it counts as wrong.
    e = fitting.error_minus_one(truth, r["labels"])
    bad = r["k"] != 3 or e > 0.05
    errors.append(e)
    wrong += bad
    found += fitting.found(truth, r["labels"], 3)
    if args.list:
        small = collections.Counter(l for l, t in zip(r["labels"], truth) if t == 3)
        print(seed, "k", r["k"], "error %.2f" % (100 * e),
              [(s["type"], s["inliers"]) for s in r["structures"]], "20-point circle:", dict(small),
              "WRONG" if bad else "")
print(f"{'k = 3' if args.k else 'K chosen'}: mean error {100 * sum(errors) / len(errors):.2f} %, "
      f"wrong {wrong}/{len(errors)}, the 20-point circle found (15 of its points in one structure) "
      f"{found}/{len(errors)}")
