"""K by a geometric label cost on refined answers, against SOD. For each sample written by
research/k-label-cost-collect.py, every answer given k = 1..8 is scored as
    cost = sum_i min(r_i^2 / sigma^2, C) + lambda * (number of structures)
(r_i the symmetric transfer distance of correspondence i to the nearest structure's model, sigma
the median over the answers of their structures' median RMS, C the cost of an outlier); the
answer of least cost is the rule's. lambda is fixed, or c * n, or c * 8 ln n (BIC-like: 8
parameters per homography). Prints, per share of rows kept: the rule's mean error and share of
K right, then SOD's (the served answer with K chosen), then the answer given the true K.

  python3 research/k-label-cost.py DATA.json"""
import collections, json, sys

import numpy as np
from scipy.optimize import linear_sum_assignment

import fitting

res = json.load(open(sys.argv[1]))


def err(pred, gt):
    """Share of points outside the best one-to-one matching of groups (-1 a group of its own)."""
    P = {v: i for i, v in enumerate(sorted(set(pred)))}
    G = {v: i for i, v in enumerate(sorted(set(gt)))}
    C = np.zeros((len(P), len(G)))
    for p, g in zip(pred, gt):
        C[P[p], G[g]] += 1
    r, c = linear_sum_assignment(-C)
    return 1 - C[r, c].sum() / len(gt)


def choose(r, lam, cost_out):
    X = np.array(r["points"], float)
    answers = [r[f"k{k}"] for k in range(1, 9)]
    models = lambda a: [s for s in a["structures"] if s["type"] != "degenerate"]
    sigma = np.median([np.median([s["rms"] for s in models(a)]) for a in answers if models(a)])
    best = None
    for a in answers:
        S = models(a)
        if not S:
            continue
        R = np.min(np.stack([fitting.transfer(s, X) for s in S]), 0) / sigma ** 2
        cost = np.minimum(R, cost_out).sum() + lam(len(X)) * len(S)
        if best is None or cost < best[0] - 1e-9:
            best = (cost, a)
    return best[1]


def table(lam, cost_out):
    out = collections.defaultdict(list)
    for r in res:
        gt = r["labels"]
        k_true = len(set(gt)) - (0 in gt)
        a = choose(r, lam, cost_out)
        out[r["share"]].append((err(a["labels"], gt), a["k"] == k_true, err(r["chosen"]["labels"], gt),
                                r["chosen"]["k"] == k_true, err(r[f"k{k_true}"]["labels"], gt)))
    return {s: " / ".join(f"{100 * np.mean([v[i] for v in rows]):.2f}" for i in range(5)) for s, rows in sorted(out.items())}


print("share: rule error / rule K right / SOD error / SOD K right / known K error (%)")
for cost_out in (9, 16):
    for name, lam in [*[(f"lambda {c}", lambda n, c=c: c) for c in (20, 40, 80, 160)],
                      *[(f"lambda {c} n", lambda n, c=c: c * n) for c in (0.2, 0.4, 0.8)],
                      *[(f"lambda {c} x 8 ln n", lambda n, c=c: c * 8 * np.log(n)) for c in (1, 2, 4)]]:
        print(f"C {cost_out:2d}, {name:16s}", table(lam, cost_out))
