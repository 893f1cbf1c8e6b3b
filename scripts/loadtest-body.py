#!/usr/bin/env python3
"""Writes a POST /v1/fit body of N correspondences for model adelaide-homography.

    scripts/loadtest-body.py N OUT [DATASET_JSON]

The rows come from AdelaideRMF unihouse (2084 correspondences, 980 x 735 pixels; default
$MULTIFIT_DATA/adelaidermf/unihouse.json, MULTIFIT_DATA defaulting to ../shared/datasets): a random
subset seeded by N when N <= 2084, else every row plus copies jittered by up to 0.5 pixel (kept
inside the image). Used by scripts/loadtest.sh and scripts/check-abandoned.sh.
"""
import json
import os
import random
import sys
from pathlib import Path

n, out = int(sys.argv[1]), sys.argv[2]
data = os.environ.get("MULTIFIT_DATA", str(Path(__file__).resolve().parent / "../../shared/datasets"))
source = sys.argv[3] if len(sys.argv) > 3 else os.path.join(data, "adelaidermf", "unihouse.json")
d = json.load(open(source))
rows, (w, h) = d["points"], d["image_size"]
rng = random.Random(n)
if n <= len(rows):
    points = rng.sample(rows, n)
else:
    points = list(rows)
    limits = (w, h, w, h)
    while len(points) < n:
        r = rows[len(points) % len(rows)]
        points.append([round(min(max(v + rng.uniform(-0.5, 0.5), 0.0), limits[i]), 3)
                       for i, v in enumerate(r)])
body = {"kind": "correspondences", "model": "adelaide-homography", "points": points,
        "image_size": [w, h], "seed": 0}
with open(out, "w") as f:
    json.dump(body, f, separators=(",", ":"))
