"""Trajectory sequences sent whole with their `visible` masks (known K, refined, outliers off):
the error on the tracks seen throughout, on the partly seen tracks placed on their motions, and
the share of tracks labelled. Needs a running server.

  python3 research/partial-tracks.py PORT DIR MODEL

MODEL names the model, or `fold-` to fit each sequence with the fold model `fold-<name>` that
never saw it (a server on a cv run's models: --models runs/cv/kt-pretrained/models)."""
import json, urllib.request, sys, glob, statistics as st
from itertools import permutations
port, data, model = sys.argv[1], sys.argv[2], sys.argv[3]
def post(r):
    req = urllib.request.Request(f"http://127.0.0.1:{port}/v1/fit", data=json.dumps(r).encode(),
                                 headers={"content-type": "application/json"})
    return json.load(urllib.request.urlopen(req))
def err(truth, lab, idx):
    if not idx: return None
    ks = sorted(set(truth[i] for i in idx)); K = max(max(lab[i] for i in idx) + 1, len(ks)); best = 0
    for p in permutations(range(K), len(ks)):
        m = dict(zip(ks, p)); best = max(best, sum(1 for i in idx if m[truth[i]] == lab[i]))
    return 1 - best / len(idx)
rows = []
for f in sorted(glob.glob(data + '/*.json')):
    d = json.load(open(f)); vis = d['visible']; n = len(vis); F = len(vis[0])
    name = model + d['name'] if model == 'fold-' else model
    o = post({"kind": "trajectories", "model": name, "points": d['points'], "visible": vis,
              "k": d['num_models'], "image_size": d['image_size'], "refine": True, "outliers": False})
    lab, truth = o['labels'], d['labels']
    comp = [i for i in range(n) if all(vis[i])]
    placed = [i for i in range(n) if not all(vis[i]) and lab[i] >= 0]
    labelled = [i for i in range(n) if lab[i] >= 0]
    r = dict(name=d['name'], n=n, complete=len(comp), placed=len(placed),
             err_complete=err(truth, lab, comp), err_placed=err(truth, lab, placed), err_labelled=err(truth, lab, labelled))
    rows.append(r)
    print(f"{r['name']:16s} n={n:4d} complete={len(comp):4d} placed={len(placed):4d} unlabelled={n-len(labelled):3d} "
          f"err complete {100*r['err_complete']:5.1f}  placed {100*(r['err_placed'] or 0):5.1f}  all labelled {100*r['err_labelled']:5.1f}")
m = lambda k: 100 * st.mean(r[k] for r in rows if r[k] is not None)
md = lambda k: 100 * st.median(r[k] for r in rows if r[k] is not None)
cov = sum(r['complete'] + r['placed'] for r in rows) / sum(r['n'] for r in rows)
cov0 = sum(r['complete'] for r in rows) / sum(r['n'] for r in rows)
print(f"{len(rows)} sequences; mean / median %: complete {m('err_complete'):.2f} / {md('err_complete'):.2f}, placed {m('err_placed'):.2f} / {md('err_placed'):.2f}, all labelled {m('err_labelled'):.2f} / {md('err_labelled'):.2f}")
print(f"tracks labelled: {100*cov:.1f} % (seen throughout: {100*cov0:.1f} %)")
