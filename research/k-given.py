"""AdelaideRMF pairs fitted with k = the number of structures (outliers not counted), refined:
per pair the true k, the answer's k and the error in % (outliers, -1, scored as the file's
outlier group), then how often k was kept and the mean error. Needs a running server.

  python3 research/k-given.py PORT MODEL [PAIR]

MODEL is adelaide-homography or adelaide-fundamental (its pairs are those of its type); PAIR
fits that pair alone. research/k-given-loo.sh runs it on each fold model of a cv run."""
import collections, glob, itertools, json, sys, urllib.request

port, model = sys.argv[1], sys.argv[2]
only = sys.argv[3] if len(sys.argv) > 3 else None
kind = "homography" if "homography" in model else "fundamental"


def post(body):
    req = urllib.request.Request(f"http://127.0.0.1:{port}/v1/fit", data=json.dumps(body).encode(),
                                 headers={"content-type": "application/json"})
    return json.load(urllib.request.urlopen(req))


def error(truth, labels):
    """Share of points outside the best one-to-one matching of answer groups to true groups."""
    ks, ts = sorted(set(labels)), sorted(set(truth))
    count = collections.Counter(zip(labels, truth))
    best = max(sum(count[(a, b)] for a, b in zip(ks, perm) if b is not None)
               for perm in itertools.permutations(ts + [None] * max(0, len(ks) - len(ts)), len(ks)))
    return 1 - best / len(truth)


rows = []
for path in sorted(glob.glob("../shared/datasets/adelaidermf/*.json")):
    d = json.load(open(path))
    if d.get("model_type") != kind or (only and d["name"] != only):
        continue
    k = len(set(d["labels"]) - {0})
    r = post({"kind": "correspondences", "model": model, "points": d["points"],
              "image_size": d["image_size"], "k": k, "refine": True})
    e = error(d["labels"], [max(l, -1) for l in r["labels"]])
    rows.append((r["k"] == k, e))
    print(d["name"], k, r["k"], round(100 * e, 2))
if not only:
    print("k kept", sum(kept for kept, _ in rows), "/", len(rows),
          "mean error", round(100 * sum(e for _, e in rows) / len(rows), 2))
