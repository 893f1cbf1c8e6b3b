"""LCE sets fitted with k = the number of shapes (gross outliers not counted) by the default
points2d model as served: how often k was kept and the mean error in % (outliers, -1, scored as
the sets' outlier group). Needs a running server.

  python3 research/k-given-lce.py PORT DIR     (DIR: gen-lce output, e.g.
  multifit-train gen-lce --out runs/data/kc-out --count 100 --seed 7101 --scale 2 --outliers 0.2)"""
import collections, glob, itertools, json, sys, urllib.request

port, data = sys.argv[1], sys.argv[2]


def post(body):
    req = urllib.request.Request(f"http://127.0.0.1:{port}/v1/fit", data=json.dumps(body).encode(),
                                 headers={"content-type": "application/json"})
    return json.load(urllib.request.urlopen(req))


def error(truth, labels):
    ks, ts = sorted(set(labels)), sorted(set(truth))
    count = collections.Counter(zip(labels, truth))
    best = max(sum(count[(a, b)] for a, b in zip(ks, perm) if b is not None)
               for perm in itertools.permutations(ts + [None] * max(0, len(ks) - len(ts)), len(ks)))
    return 1 - best / len(truth)


errors, kept = [], 0
for path in sorted(glob.glob(f"{data}/*.json")):
    s = json.load(open(path))
    k = len(set(s["labels"]) - {0})
    r = post({"kind": "points2d", "points": s["points"], "k": k})
    errors.append(error(s["labels"], [max(l, -1) for l in r["labels"]]))
    kept += r["k"] == k
print(data, "k kept", kept, "/", len(errors), "mean error", round(100 * sum(errors) / len(errors), 2))
