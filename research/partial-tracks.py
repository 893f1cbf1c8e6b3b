"""Trajectory sequences sent whole with their `visible` masks (known K, refined, outliers off):
the error on the tracks seen throughout, on the partly seen tracks placed on their motions, the
share of tracks labelled, and how many sequences draw the warning that placed tracks lie far from
their structure. With --hide-one, one object's tracks seen throughout (the largest motion but the
one of the smallest label, the background in gen-motion's files) are hidden in 2 to F/3 of their
first or last frames: no track of that motion is seen throughout. Needs a running server.

  python3 research/partial-tracks.py PORT DIR MODEL [--hide-one]

MODEL names the model, or `fold-` to fit each sequence with the fold model `fold-<name>` that
never saw it (a server on a cv run's models: --models runs/cv/kt-pretrained/models)."""
import json, urllib.request, sys, glob, random, statistics as st
from itertools import permutations
port, data, model = sys.argv[1], sys.argv[2], sys.argv[3]
hide = "--hide-one" in sys.argv[4:]
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
    if hide:
        rng = random.Random(d['name'])
        objects = sorted(set(d['labels']))[1:]
        target = max(objects, key=lambda l: sum(1 for i in range(n) if d['labels'][i] == l and all(vis[i])))
        for i in range(n):
            if d['labels'][i] == target and all(vis[i]):
                cut = rng.randint(2, max(2, F // 3))
                vis[i] = [int(j >= cut) for j in range(F)] if rng.random() < 0.5 else [int(j < F - cut) for j in range(F)]
    name = model + d['name'] if model == 'fold-' else model
    o = post({"kind": "trajectories", "model": name, "points": d['points'], "visible": vis,
              "k": d['num_models'], "image_size": d['image_size'], "refine": True, "outliers": False})
    lab, truth = o['labels'], d['labels']
    comp = [i for i in range(n) if all(vis[i])]
    placed = [i for i in range(n) if not all(vis[i]) and lab[i] >= 0]
    labelled = [i for i in range(n) if lab[i] >= 0]
    warned = any('partly seen tracks placed on structure' in w for w in o['warnings'])
    r = dict(name=d['name'], n=n, complete=len(comp), placed=len(placed), warned=warned,
             err_complete=err(truth, lab, comp), err_placed=err(truth, lab, placed), err_labelled=err(truth, lab, labelled))
    rows.append(r)
    print(f"{r['name']:16s} n={n:4d} complete={len(comp):4d} placed={len(placed):4d} unlabelled={n-len(labelled):3d} "
          f"err complete {100*r['err_complete']:5.1f}  placed {100*(r['err_placed'] or 0):5.1f}  all labelled {100*r['err_labelled']:5.1f}"
          f"{'  warned' if warned else ''}")
m = lambda k: 100 * st.mean(r[k] for r in rows if r[k] is not None)
md = lambda k: 100 * st.median(r[k] for r in rows if r[k] is not None)
cov = sum(r['complete'] + r['placed'] for r in rows) / sum(r['n'] for r in rows)
cov0 = sum(r['complete'] for r in rows) / sum(r['n'] for r in rows)
print(f"{len(rows)} sequences; mean / median %: complete {m('err_complete'):.2f} / {md('err_complete'):.2f}, placed {m('err_placed'):.2f} / {md('err_placed'):.2f}, all labelled {m('err_labelled'):.2f} / {md('err_labelled'):.2f}")
print(f"tracks labelled: {100*cov:.1f} % (seen throughout: {100*cov0:.1f} %)")
print(f"sequences warned that placed tracks lie far from their structure: {sum(r['warned'] for r in rows)} of {len(rows)}")
