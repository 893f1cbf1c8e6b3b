"""Type of each true LCE structure's answer: every set of the mixed variant (labels 1..4 are
one line, two ellipses and one circle) is fitted with its true K, and each true structure is
counted under the type of the structure that holds most of its points. Needs a running server.

  python3 research/curve-types.py PORT DIR [DIR ...]   (DIR: gen-lce output of the mixed variant)"""
import collections, glob, json, sys, urllib.request

TRUE = {1: "line", 2: "ellipse", 3: "ellipse", 4: "circle"}
port = sys.argv[1]
for d in sys.argv[2:]:
    counts = collections.Counter()
    for fn in sorted(glob.glob(d + "/*.json")):
        f = json.load(open(fn))
        body = json.dumps({"kind": "points2d", "points": f["points"], "k": f["num_models"]}).encode()
        req = urllib.request.Request(f"http://127.0.0.1:{port}/v1/fit", body,
                                     {"content-type": "application/json"})
        v = json.load(urllib.request.urlopen(req))
        types = {s["label"]: s["type"] for s in v["structures"]}
        for g in sorted(set(f["labels"])):
            held = collections.Counter(l for l, t in zip(v["labels"], f["labels"]) if t == g)
            counts[(TRUE[g], types.get(held.most_common(1)[0][0], "outlier"))] += 1
    print(d, ", ".join(f"{t} as {a}: {c}" for (t, a), c in sorted(counts.items())))
