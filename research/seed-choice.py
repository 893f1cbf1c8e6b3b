"""Best of several k-means seeds by the truncated cost: each AdelaideRMF homography pair fitted
with k given and `seed` 0..3 in the files' order and in shuffled orders, each answer's
structures scored by sum_i min(d_i^2, tau^2) (d_i: the row's smallest symmetric transfer
distance to a structure), and the error of the answer of least cost among the first m seeds
reported against seed 0 alone. Needs a running server.

  python3 research/seed-choice.py PORT ORDERS_DIR
      ORDERS_DIR: shuffled copies from research/row-orders.py make (every s* under it is read)
"""
import glob, json, sys

import numpy as np

import fitting

port, orders = sys.argv[1], sys.argv[2]
dirs = ["../shared/datasets/adelaidermf"] + sorted(glob.glob(f"{orders}/s*"))


answers = []  # per (pair, order): [(error, distances, median rms, structures)] for seeds 0..3
for path in sorted(glob.glob(dirs[0] + "/*.json")):
    name = json.load(open(path))["name"]
    for d in dirs:
        f = json.load(open(f"{d}/{name}.json"))
        if f.get("model_type") != "homography":
            break
        P = np.array(f["points"], float)
        k = len(set(f["labels"]) - {0})
        per = []
        for seed in range(4):
            r = fitting.post(port, {"kind": "correspondences", "model": "adelaide-homography",
                                    "k": k, "points": f["points"], "image_size": f["image_size"],
                                    "seed": seed})
            dist = np.sqrt(np.stack([fitting.transfer(s, P) for s in r["structures"]] or [np.full(len(P), np.inf)]))
            dmin = np.nan_to_num(dist.min(0), nan=1e9, posinf=1e9)
            err = fitting.error(f["labels"], [max(l, -1) for l in r["labels"]])
            rms = np.median([s["rms"] for s in r["structures"]]) if r["structures"] else np.inf
            per.append((err, dmin, rms, len(r["structures"])))
        answers.append(per)

for label, tau_of in [("tau = 5 px", lambda per: 5.0),
                      ("tau = 3 x the smaller median RMS", lambda per: 3 * min(a[2] for a in per))]:
    best = {m: [] for m in (1, 2, 3, 4)}
    for per in answers:
        tau = tau_of(per)
        cost = [np.minimum(a[1] ** 2, tau ** 2).sum() if a[3] == per[0][3] else np.inf for a in per]
        for m in best:
            best[m].append(per[min(range(m), key=lambda i: cost[i])][0])
    print(label, ", ".join(f"best of {m} seeds {100 * np.mean(v):.2f} %" for m, v in best.items()))
