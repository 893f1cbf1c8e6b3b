"""Crossing curves in pixels, as a new user would draw them: a line, a circle and an ellipse
around the middle of a 640 x 480 image (the circle and the ellipse drawn around nearby centres,
so most layouts cross), 100 points each, with Gaussian noise of 0.5, 1 and 2 px and 0 or 20 %
gross outliers uniform over the image, rows shuffled; 20 layouts (seeds) under each of the 6
conditions, 120 sets. Each set is
fitted with the card's defaults (K chosen) and, with --k, given k = 3. Prints the mean error (in
%, outliers scored as one more group) and how many answers are wrong (k not 3, or over 5 %
error). Needs a running server.

  python3 research/crossing-curves.py PORT [--k] [--list]"""
import math, random, sys

import fitting


def crossing(seed, noise, outliers, n=100):
    """(points, labels): the line 1, the circle 2, the ellipse 3, outliers 0."""
    rng = random.Random(seed)
    points, labels = [], []
    a, cx, cy = rng.uniform(0, math.pi), rng.uniform(200, 440), rng.uniform(150, 330)
    for _ in range(n):
        t = rng.uniform(-200, 200)
        points.append([cx + t * math.cos(a) + rng.gauss(0, noise),
                       cy + t * math.sin(a) + rng.gauss(0, noise)])
        labels.append(1)
    ccx, ccy, r = rng.uniform(220, 420), rng.uniform(180, 300), rng.uniform(60, 140)
    for _ in range(n):
        t, rr = rng.uniform(0, 2 * math.pi), r + rng.gauss(0, noise)
        points.append([ccx + rr * math.cos(t), ccy + rr * math.sin(t)])
        labels.append(2)
    ex, ey = rng.uniform(220, 420), rng.uniform(180, 300)
    ea, eb, th = rng.uniform(100, 180), rng.uniform(40, 90), rng.uniform(0, math.pi)
    for _ in range(n):
        t = rng.uniform(0, 2 * math.pi)
        u, v = ea * math.cos(t), eb * math.sin(t)
        points.append([ex + u * math.cos(th) - v * math.sin(th) + rng.gauss(0, noise),
                       ey + u * math.sin(th) + v * math.cos(th) + rng.gauss(0, noise)])
        labels.append(3)
    for _ in range(round(outliers * len(points) / (1 - outliers))):
        points.append([rng.uniform(0, 640), rng.uniform(0, 480)])
        labels.append(0)
    # Rows in no particular order, as a detector or a scanner would give them.
    order = list(range(len(points)))
    rng.shuffle(order)
    return [points[i] for i in order], [labels[i] for i in order]


def main():
    port = sys.argv[1]
    extra = {"k": 3} if "--k" in sys.argv else {}
    errors, wrong = [], 0
    for outliers in (0.0, 0.2):
        for noise in (0.5, 1.0, 2.0):
            for seed in range(20):
                points, truth = crossing(seed, noise, outliers)
                answer = fitting.post(port, {"kind": "points2d", "points": points, "model": "lce",
                                             **extra})
                e = fitting.error(truth, answer["labels"])
                errors.append(e)
                bad = answer["k"] != 3 or e > 0.05
                wrong += bad
                if bad and "--list" in sys.argv:
                    print(f"outliers {outliers} noise {noise} seed {seed}: k {answer['k']}, "
                          f"{100 * e:.1f} %")
    print(f"mean error {100 * sum(errors) / len(errors):.2f} %, wrong {wrong} of {len(errors)}")


if __name__ == "__main__":
    main()
