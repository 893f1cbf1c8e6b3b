#!/usr/bin/env python3
"""Rules for choosing K from the k-means residual curve, scored on evaluated samples, with the
rule chosen for each sample without looking at it (leave one out: the rule with the lowest mean
error on the other samples).

The rules, each a function of the curve r(1), r(2), ... alone (l = log r):
  sod          the paper's: argmax over inner K of l(K-1) + l(K+1) - 2 l(K) (K = 1 when
               r(1) / n < 0.01, as the server does; checked against each row's own SOD pick)
  sod-linear   the same on r instead of l
  spread:t     the smallest K with r(K) / n below t (the mean squared distance of a point to its
               centre; embeddings have unit length)
  drop:t       the largest K whose drop l(K-1) - l(K) exceeds t (1 when none does)

Usage: research/k-rules.py FILE [FILE ...]
Each FILE is `eval --json` output, a kept-eval*.json of scripts/cv-eval-kept.sh or a cv per-fold
JSON; its rows need `residuals` and `errors_by_k` (not every file under docs/results/ has them).
"""
import json
import math
import statistics as st
import sys

from loo import choose_without


def rows_of(path):
    d = json.load(open(path))
    if "rows" in d:
        return d["rows"]
    return [d["row"]]


def sod(r, k_max):
    l = [math.log(x + r[0] * 1e-9 + 1e-12) for x in r]
    inner = [(l[i - 1] + l[i + 1] - 2 * l[i], i + 1) for i in range(1, min(len(r) - 1, k_max))]
    return max(inner, key=lambda s: (s[0], -s[1]))[1]


def sod_linear(r, k_max):
    inner = [(r[i - 1] + r[i + 1] - 2 * r[i], i + 1) for i in range(1, min(len(r) - 1, k_max))]
    return max(inner, key=lambda s: (s[0], -s[1]))[1]


def spread(t):
    def rule(r, k_max, n):
        return next((k for k in range(1, k_max + 1) if r[k - 1] / n < t), k_max)
    return rule


def drop(t):
    def rule(r, k_max, n):
        l = [math.log(x + r[0] * 1e-9 + 1e-12) for x in r]
        ks = [k for k in range(2, k_max + 1) if l[k - 2] - l[k - 1] > t]
        return max(ks) if ks else 1
    return rule


def single_or(rule):
    """As the server does: K = 1 when r(1) / n is under 0.01 (one tight group), else `rule`."""
    return lambda r, k, n: 1 if r[0] / n < 0.01 else rule(r, k)


RULES = {"sod": single_or(sod), "sod-linear": single_or(sod_linear)}
RULES.update({f"spread:{t}": spread(t) for t in [0.005, 0.01, 0.02, 0.05, 0.1, 0.2]})
RULES.update({f"drop:{t}": drop(t) for t in [0.1, 0.2, 0.3, 0.5, 0.7, 1.0]})


def main():
    rows = [r for p in sys.argv[1:] for r in rows_of(p)]
    if not rows:
        sys.exit(__doc__)
    for r in rows:
        if not r.get("residuals") or not r.get("errors_by_k"):
            sys.exit(f"{r['name']}: no residual curve or per-K errors (evaluate again)")
    names = list(RULES)
    pick = {n: [] for n in names}
    for r in rows:
        k_max = len(r["errors_by_k"])
        for n in names:
            pick[n].append(RULES[n](r["residuals"], k_max, r["n"]))
    for r, k in zip(rows, pick["sod"]):
        if k != r["sod"]["k"]:
            sys.exit(f"{r['name']}: sod here picks {k}, the evaluation {r['sod']['k']}")
    err = {n: [r["errors_by_k"][k - 1] for r, k in zip(rows, pick[n])] for n in names}
    right = {n: [k == r["k_true"] for r, k in zip(rows, pick[n])] for n in names}
    print(f"{len(rows)} samples; each rule on all of them (its best chosen on them flatters):")
    for n in names:
        print(f"  {n:12s} mean {100 * st.mean(err[n]):6.2f}  median {100 * st.median(err[n]):6.2f}"
              f"  K right {100 * st.mean(right[n]):5.1f} %")
    chosen = choose_without(err, names)
    counts = {n: chosen.count(n) for n in dict.fromkeys(chosen)}
    e = [err[n][i] for i, n in enumerate(chosen)]
    ok = [right[n][i] for i, n in enumerate(chosen)]
    print(f"  rule chosen without the sample: mean {100 * st.mean(e):.2f}  median "
          f"{100 * st.median(e):.2f}  K right {100 * st.mean(ok):.1f} %  (chosen: "
          + ", ".join(f"{n} {c}" for n, c in sorted(counts.items(), key=lambda x: -x[1])) + ")")


if __name__ == "__main__":
    main()
