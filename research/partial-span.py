"""Partly seen tracks, fitted another way (RESULTS, "Tracks seen in some frames", tried): the
tracks seen throughout one span of frames are fitted (known K, refined), the span chosen by RULE
(nL: most tracks x frames; nsqrtL: tracks x sqrt(frames); n: most tracks, at least 5 frames),
and every other track seen in 3 or more of its frames is placed on the nearest motion subspace
over them (residual per degree of freedom), against the server's own fit of the sequence sent
whole with its visible mask. Needs a running server (numpy).

  python3 research/partial-span.py PORT DIR MODEL RULE    (MODEL fold-: each sequence's fold model)"""
import json, sys, glob, statistics as st
import numpy as np
sys.path.insert(0, 'research')
from fitting import error, post
port, data, model, rule = sys.argv[1], sys.argv[2], sys.argv[3], sys.argv[4]
def err(truth, lab, idx):
    """The error on the tracks `idx` alone."""
    return error([truth[i] for i in idx], [lab[i] for i in idx]) if idx else None
def span_of(vis, rule):
    n, F = vis.shape; best = None
    for a in range(F):
        for b in range(a + min(F, 5) - 1, F):
            L = b - a + 1; cnt = int(vis[:, a:b + 1].all(1).sum())
            if cnt < 10: continue
            sc = {'nL': cnt * L, 'nsqrtL': cnt * L ** 0.5, 'n': cnt + 1e-3 * L, 'all': (L == F) * 1e9 + cnt}[rule]
            if best is None or sc > best[0]: best = (sc, a, b)
    return best[1], best[2]
R = []
for f in sorted(glob.glob(data + '/*.json')):
    d = json.load(open(f)); vis = np.array(d['visible'], bool); n, F = vis.shape
    name = model + d['name'] if model == 'fold-' else model
    pts = d['points']; truth = d['labels']; k = d['num_models']
    P = np.array([[np.nan if v is None else v for v in r] for r in pts], float).reshape(n, F, 2)
    base = post(port, {"kind": "trajectories", "model": name, "points": pts, "visible": d['visible'],
                "k": k, "image_size": d['image_size'], "refine": True, "outliers": False})['labels']
    a, b = span_of(vis, rule)
    inside = [i for i in range(n) if vis[i, a:b + 1].all()]
    rows = [P[i, a:b + 1].reshape(-1).tolist() for i in inside]
    o = post(port, {"kind": "trajectories", "model": name, "points": rows, "k": min(k, len(rows)),
                    "image_size": d['image_size'], "refine": True, "outliers": False})
    lab = [-1] * n
    for i, l in zip(inside, o['labels']): lab[i] = l
    mot = [(s['label'], np.array(s['params']['mean']), np.array(s['params']['basis'])) for s in o['structures'] if s['type'] == 'subspace']
    for i in range(n):
        if lab[i] >= 0: continue
        S = vis[i, a:b + 1]
        if S.sum() < 3 or not mot: continue
        cs = np.repeat(S, 2)
        x = P[i, a:b + 1].reshape(-1)[cs]
        best = None
        for l, m, B in mot:
            Bs = B[:, cs].T; r = Bs.shape[1]
            if cs.sum() <= r: continue
            c, *_ = np.linalg.lstsq(Bs, x - m[cs], rcond=None)
            e2 = float(((x - m[cs] - Bs @ c) ** 2).sum()) / (cs.sum() - r)
            if best is None or e2 < best[0]: best = (e2, l)
        if best: lab[i] = best[1]
    L0 = [i for i in range(n) if base[i] >= 0]; L1 = [i for i in range(n) if lab[i] >= 0]
    e0, e1 = err(truth, base, L0), err(truth, lab, L1)
    R.append((len(L0) / n, e0, len(L1) / n, e1))
    print(f"{d['name'][:16]:16s} F={F:3d} span {a}..{b} inside={len(inside):4d}/{n:4d}  server: {100*len(L0)/n:5.1f}% labelled, err {100*e0:5.1f} | span: {100*len(L1)/n:5.1f}%, err {100*e1:5.1f}")
m = lambda j: 100 * st.mean(r[j] for r in R)
print(f"rule {rule}: server labelled {m(0):.1f} % err {m(1):.2f} | span labelled {m(2):.1f} % err {m(3):.2f} ({len(R)} sequences)")
