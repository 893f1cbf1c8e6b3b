#!/usr/bin/env python3
"""A classical baseline for LCE: sequential RANSAC given the true types and counts.

The paper's Table 1 reports this kind of baseline ("Seq.": RPA 23.17 %, RansaCov 24.04 % error),
which is told the type and number of every structure. Running a comparable baseline on our own
generator tells how hard our data is next to the authors' (whose generator is not public).

For each sample the structures are fitted one after another, simplest first (lines, circles, then
ellipses): RANSAC draws minimal sets (2, 3, 5 points) from the points not yet taken, keeps the
hypothesis with most inliers (distance below --threshold, default 2 sigma = 0.1), refits it to
its inliers by least squares (Fitzgibbon's direct fit for ellipses) and removes them. At the end
every point goes to the model with the smallest residual, and the error is the misclassification
rate under the best matching of labels, as for the network.

    python3 research/lce-ransac.py runs/data/lce-test [--hypotheses 1000] [--seed 0]

Needs numpy and scipy. Reads the JSON samples written by `multifit-train gen-lce`.
"""

import argparse
import json
import re
from pathlib import Path

import numpy as np
from scipy.optimize import linear_sum_assignment

EPS = 1e-12


def conic_rows(p: np.ndarray) -> np.ndarray:
    """points [..., 2] -> design rows [..., 6] of a x^2 + b xy + c y^2 + d x + e y + f."""
    x, y = p[..., 0], p[..., 1]
    return np.stack([x * x, x * y, y * y, x, y, np.ones_like(x)], axis=-1)


def sampson(conics: np.ndarray, p: np.ndarray) -> np.ndarray:
    """conics [h, 6], points [n, 2] -> first-order geometric distance [h, n]."""
    a, b, c, d, e, f = conics.T[:, :, None]
    x, y = p[:, 0][None], p[:, 1][None]
    alg = a * x * x + b * x * y + c * y * y + d * x + e * y + f
    gx = 2 * a * x + b * y + d
    gy = b * x + 2 * c * y + e
    return np.abs(alg) / np.sqrt(gx * gx + gy * gy + EPS)


def line_hyp(s: np.ndarray) -> np.ndarray:
    """samples [h, 2, 2] -> lines as conics [h, 6] (0 x^2 + ... + d x + e y + f)."""
    p, q = s[:, 0], s[:, 1]
    n = np.stack([q[:, 1] - p[:, 1], p[:, 0] - q[:, 0]], axis=1)
    n /= np.linalg.norm(n, axis=1, keepdims=True) + EPS
    f = -(n * p).sum(1)
    z = np.zeros(len(s))
    return np.stack([z, z, z, n[:, 0], n[:, 1], f], axis=1)


def circle_hyp(s: np.ndarray) -> np.ndarray:
    """samples [h, 3, 2] -> circles as conics [h, 6]: x^2 + y^2 + d x + e y + f."""
    x, y = s[..., 0], s[..., 1]
    a = np.stack([x, y, np.ones_like(x)], axis=-1)
    rhs = -(x * x + y * y)
    ok = np.abs(np.linalg.det(a)) > 1e-9
    sol = np.zeros((len(s), 3))
    sol[ok] = np.linalg.solve(a[ok], rhs[ok][..., None])[..., 0]
    o = np.ones(len(s))
    z = np.zeros(len(s))
    conics = np.stack([o, z, o, sol[:, 0], sol[:, 1], sol[:, 2]], axis=1)
    conics[~ok] = np.nan
    return conics


def ellipse_hyp(s: np.ndarray) -> np.ndarray:
    """samples [h, 5, 2] -> the conics through the 5 points [h, 6]; non-ellipses are NaN."""
    _, _, vt = np.linalg.svd(conic_rows(s))
    conics = vt[:, -1, :]
    a, b, c = conics[:, 0], conics[:, 1], conics[:, 2]
    conics[b * b - 4 * a * c >= 0] = np.nan
    return conics


def fit_line(p: np.ndarray) -> np.ndarray:
    m = p.mean(0)
    _, _, vt = np.linalg.svd(p - m)
    n = vt[-1]
    return np.array([0, 0, 0, n[0], n[1], -n @ m])


def fit_circle(p: np.ndarray) -> np.ndarray:
    a = np.column_stack([p, np.ones(len(p))])
    sol, *_ = np.linalg.lstsq(a, -(p**2).sum(1), rcond=None)
    return np.array([1, 0, 1, *sol])


def fit_ellipse(p: np.ndarray) -> np.ndarray:
    """Fitzgibbon, Pilu and Fisher's direct least-squares ellipse fit (Halir-Flusser form)."""
    m, sc = p.mean(0), p.std() + EPS
    q = (p - m) / sc
    d = conic_rows(q)
    s = d.T @ d
    s1, s2, s3 = s[:3, :3], s[:3, 3:], s[3:, 3:]
    try:
        t = -np.linalg.solve(s3, s2.T)
    except np.linalg.LinAlgError:
        return np.full(6, np.nan)
    mm = s1 + s2 @ t
    mm = np.array([mm[2] / 2, -mm[1], mm[0] / 2])
    w, v = np.linalg.eig(mm)
    v = np.real(v)
    cond = 4 * v[0] * v[2] - v[1] ** 2
    idx = np.where(cond > 0)[0]
    if len(idx) == 0:
        return np.full(6, np.nan)
    a1 = v[:, idx[0]]
    a, b, c, dd, e, f = np.concatenate([a1, t @ a1])
    # Undo the normalisation: substitute x -> (x - mx) / sc, y -> (y - my) / sc.
    mx, my = m
    a, b, c, dd, e = a / sc**2, b / sc**2, c / sc**2, dd / sc, e / sc
    return np.array([
        a, b, c,
        dd - 2 * a * mx - b * my,
        e - 2 * c * my - b * mx,
        a * mx * mx + b * mx * my + c * my * my - dd * mx - e * my + f,
    ])


MODELS = {
    "line": (2, line_hyp, fit_line),
    "circle": (3, circle_hyp, fit_circle),
    "ellipse": (5, ellipse_hyp, fit_ellipse),
}


def ransac(kind: str, p: np.ndarray, hyps: int, thr: float, rng) -> np.ndarray:
    """points [n, 2] -> the best conic [6] of this kind, refit to its inliers."""
    m, hyp, fit = MODELS[kind]
    if len(p) < m:
        return np.full(6, np.nan)
    idx = np.array([rng.choice(len(p), m, replace=False) for _ in range(hyps)])
    conics = hyp(p[idx])
    good = ~np.isnan(conics).any(1)
    if not good.any():
        return np.full(6, np.nan)
    conics = conics[good]
    counts = (sampson(conics, p) < thr).sum(1)
    best = conics[counts.argmax()]
    inl = sampson(best[None], p)[0] < thr
    if inl.sum() >= m:
        refit = fit(p[inl])
        if not np.isnan(refit).any():
            best = refit
    return best


def error_rate(truth: np.ndarray, pred: np.ndarray) -> float:
    k = max(truth.max(), pred.max()) + 1
    c = np.zeros((k, k))
    np.add.at(c, (truth, pred), 1)
    r, cidx = linear_sum_assignment(-c)
    return 1.0 - c[r, cidx].sum() / len(truth)


def nmi(truth: np.ndarray, pred: np.ndarray) -> float:
    """I(T; P) / ((H(T) + H(P)) / 2), the arithmetic normalisation of src/metrics.rs."""
    c = np.zeros((truth.max() + 1, pred.max() + 1))
    np.add.at(c, (truth, pred), 1)
    pxy = c / c.sum()
    px, py = pxy.sum(1), pxy.sum(0)
    nz = pxy > 0
    mi = (pxy[nz] * np.log(pxy[nz] / np.outer(px, py)[nz])).sum()
    h = lambda q: -(q[q > 0] * np.log(q[q > 0])).sum()
    denom = (h(px) + h(py)) / 2
    return 1.0 if denom <= 0 else float(np.clip(mi / denom, 0.0, 1.0))


SHAPES = re.compile(r"shapes \[([A-Za-z, ]+)\]")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("data", type=Path, help="directory of sample JSON files")
    ap.add_argument("--hypotheses", type=int, default=1000)
    ap.add_argument("--threshold", type=float, default=0.1)
    ap.add_argument("--seed", type=int, default=0)
    a = ap.parse_args()
    files = sorted(a.data.glob("*.json"))
    if not files:
        raise SystemExit(f"{a.data}: no .json samples")
    rng = np.random.default_rng(a.seed)
    order = {"line": 0, "circle": 1, "ellipse": 2}
    errors, nmis = [], []
    for f in files:
        s = json.loads(f.read_text())
        p = np.asarray(s["points"], dtype=float)
        truth = np.asarray(s["labels"], dtype=int) - 1
        found = SHAPES.search(s.get("source") or "")
        if not found:
            raise SystemExit(f"{f}: no shape list in 'source'")
        kinds = sorted((k.strip().lower() for k in found.group(1).split(",")), key=order.get)
        left = np.ones(len(p), bool)
        conics = []
        for kind in kinds:
            c = ransac(kind, p[left], a.hypotheses, a.threshold, rng)
            conics.append(c)
            if not np.isnan(c).any():
                left &= ~(sampson(c[None], p)[0] < a.threshold)
        res = np.stack([
            sampson(c[None], p)[0] if not np.isnan(c).any() else np.full(len(p), np.inf)
            for c in conics
        ])
        pred = res.argmin(0)
        errors.append(error_rate(truth, pred))
        nmis.append(nmi(truth, pred))
    e = np.array(errors)
    print(f"{a.data}: {len(e)} samples, sequential RANSAC with true types and counts "
          f"({a.hypotheses} hypotheses, threshold {a.threshold})")
    print(f"error mean {100 * e.mean():.2f} %, median {100 * np.median(e):.2f} %, "
          f"NMI mean {np.mean(nmis):.3f}")


if __name__ == "__main__":
    main()
