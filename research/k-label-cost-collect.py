"""K by a geometric label cost, data: for every AdelaideRMF homography pair, as sent and in three
seeded draws of 25 % and 50 % of its rows, the refined answers of a server given k = 1..8 and
its answer with K chosen (refine and outliers on), written as JSON for research/k-label-cost.py.
The server should serve the fold models (`--models runs/cv/adelaide-homography-mimi-twoview-ft10/models`),
each pair fitted by the fold model that never saw it.

  python3 research/k-label-cost-collect.py PORT OUT.json [SEED [SHARES]]   (from the repository root)
      e.g. SEED 5000, SHARES 0.25,0.5,1"""
import json, sys, glob, urllib.request, numpy as np
port, out = sys.argv[1], sys.argv[2]
seed = int(sys.argv[3]) if len(sys.argv) > 3 else 5000
shares = [float(x) for x in (sys.argv[4] if len(sys.argv) > 4 else "0.25,0.5,1").split(",")]
def post(body):
    req = urllib.request.Request(f"http://127.0.0.1:{port}/v1/fit", json.dumps(body).encode(), {"content-type": "application/json"})
    try: return json.load(urllib.request.urlopen(req))
    except urllib.error.HTTPError as e: return {"error": e.read().decode()}
res = []
files = sorted(f for f in glob.glob("../shared/datasets/adelaidermf/*.json") if json.load(open(f))["model_type"] == "homography")
for f in files:
    d = json.load(open(f)); name = d["name"]
    for share in shares:
        for draw in range(3 if share < 1 else 1):
            rs = np.random.RandomState(seed + 97 * draw + int(share * 1000))
            n = len(d["points"]); keep = np.sort(rs.permutation(n)[:max(2, round(share * n))])
            pts = [d["points"][i] for i in keep]; lab = [d["labels"][i] for i in keep]
            base = {"kind": "correspondences", "model": "fold-" + name, "points": pts, "image_size": d["image_size"], "refine": True, "outliers": True}
            r = {"name": name, "share": share, "draw": draw, "labels": lab, "points": pts}
            for k in range(1, 9):
                a = post({**base, "k": k}); r[f"k{k}"] = {x: a.get(x) for x in ("labels", "k", "structures", "error", "warnings")}
            a = post(base); r["chosen"] = {x: a.get(x) for x in ("labels", "k", "structures", "error", "scores")}
            res.append(r)
            print(name, share, draw, len(pts), len(set(lab)) - (0 in lab), a.get("k"), [r[f"k{k}"]["k"] for k in range(1, 9)], flush=True)
json.dump(res, open(out, "w"))
