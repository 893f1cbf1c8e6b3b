"""Near copies: LCE sets sent as they are, twice, and with a copy of every point a small
distance off (in a random direction), each fitted with its true K; the mean error over the
original rows of each variant. Copies 1e-3 to 1e-2 of the set's RMS spread off are one point
seen twice, and should answer as the set alone.

  python3 research/near-copies.py PORT DIR COUNT [FIRST [SEED]]
      e.g. DIR = runs/data/lce2-test (gen-lce --count 200 --seed 4 --scale 2): the first COUNT
      sets from set FIRST (default 0), jitter directions drawn with SEED (default 3)"""
import glob, json, sys

import numpy as np

from fitting import error, post

port, src, count = sys.argv[1], sys.argv[2], int(sys.argv[3])
first = int(sys.argv[4]) if len(sys.argv) > 4 else 0
rs = np.random.RandomState(int(sys.argv[5]) if len(sys.argv) > 5 else 3)
names = ["as sent", "twice", "1e-3 off", "1e-4 off", "1e-2 spread off", "3e-3 off", "5e-3 spread off"]
out = {v: [] for v in names}
for path in sorted(glob.glob(f"{src}/*.json"))[first:first + count]:
    s = json.load(open(path))
    points, truth, n = np.array(s["points"], float), s["labels"], len(s["points"])
    spread = np.sqrt(((points - points.mean(0)) ** 2).sum(1).mean())

    def off(distance):
        v = rs.normal(size=points.shape)
        return points + distance * v / np.linalg.norm(v, axis=1, keepdims=True)

    variants = [points, np.vstack([points, points]), np.vstack([points, off(1e-3)]),
                np.vstack([points, off(1e-4)]), np.vstack([points, off(1e-2 * spread)]),
                np.vstack([points, off(3e-3)]), np.vstack([points, off(5e-3 * spread)])]
    for name, rows in zip(names, variants):
        answer = post(port, {"kind": "points2d", "points": rows.tolist(), "k": s["num_models"]})
        out[name].append(error(truth, answer["labels"][:n]))
print(f"{len(out['as sent'])} sets, known K, mean error %:")
for name, errors in out.items():
    print(f"  {name:16s} {100 * np.mean(errors):.2f}")
