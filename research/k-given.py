"""Fits given k = the number of structures (outliers not counted), refined: how often the answer
kept k and the mean error in % (outliers, -1, scored as the data's outlier group). Needs a
running server.

  python3 research/k-given.py PORT MODEL [PAIR]   AdelaideRMF pairs of MODEL's type
                                                  (adelaide-homography or adelaide-fundamental),
                                                  one line per pair; PAIR fits that pair alone
  python3 research/k-given.py PORT DIR            LCE sets written by gen-lce, e.g.
      multifit-train gen-lce --out runs/data/kc-out --count 100 --seed 7101 --scale 2 --outliers 0.2

REFINE=0 in the environment fits without refinement; ADELAIDE=DIR reads the pairs from DIR
(for example rows shuffled by research/row-orders.py); K=auto sends no k (the card's selection
chooses K), and "k kept" then counts answers whose k is the number of structures.
research/k-given-loo.sh runs it on each fold model of a cv run."""
import glob, json, os, sys

import fitting
from fitting import error

port, what = sys.argv[1], sys.argv[2]
only = sys.argv[3] if len(sys.argv) > 3 else None


def post(body):
    return fitting.post(port, body)


def requests():
    """(name, file, request body) of every set to fit."""
    if os.path.isdir(what):
        for path in sorted(glob.glob(f"{what}/*.json")):
            s = json.load(open(path))
            yield s["name"], s, {"kind": "points2d", "points": s["points"]}
        return
    kind = "homography" if "homography" in what else "fundamental"
    for path in sorted(glob.glob(os.environ.get("ADELAIDE", "../shared/datasets/adelaidermf") + "/*.json")):
        d = json.load(open(path))
        if d.get("model_type") == kind and (not only or d["name"] == only):
            yield d["name"], d, {"kind": "correspondences", "model": what, "points": d["points"],
                                 "image_size": d["image_size"]}


rows = []
for name, data, body in requests():
    k = len(set(data["labels"]) - {0})
    given = {} if os.environ.get("K") == "auto" else {"k": k}
    r = post({**body, **given, "refine": os.environ.get("REFINE", "1") == "1"})
    e = error(data["labels"], [max(l, -1) for l in r["labels"]])
    rows.append((r["k"] == k, e))
    if not os.path.isdir(what):
        print(name, k, r["k"], round(100 * e, 2))
if not only:
    print("k kept", sum(kept for kept, _ in rows), "/", len(rows),
          "mean error", round(100 * sum(e for _, e in rows) / len(rows), 2))
