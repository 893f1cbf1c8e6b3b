"""What the scripts that fit against a running server share (imported, not run): one POST to
/v1/fit, the error of an answer under the best one-to-one matching of groups (with -1 as the
outliers' label, or not), whether one true group was found, and the squared symmetric transfer
distance of correspondences to an answered homography or affinity (numpy, imported there)."""
import collections, itertools, json, urllib.request


def post(port, body):
    """The answer of a server on 127.0.0.1:`port` to the fit request `body`."""
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


def error_minus_one(truth, labels):
    """Share of points outside the best one-to-one matching of the answer's structures to the
    true structures, outliers (truth 0) matched to -1: a structure's point answered -1 and an
    outlier answered as a structure's are both outside it."""
    kept = [(t, l) for t, l in zip(truth, labels) if l >= 0 and t > 0]
    matched = (1 - error([t for t, _ in kept], [l for _, l in kept])) * len(kept) if kept else 0
    matched += sum(1 for t, l in zip(truth, labels) if t == 0 and l == -1)
    return 1 - matched / len(truth)


def found(truth, labels, group):
    """Whether the answer holds true group `group` in a structure of its own: 75 % of its points
    in one structure (not -1) of at most 1.25 times its count."""
    n = sum(1 for t in truth if t == group)
    label, count = collections.Counter(l for l, t in zip(labels, truth) if t == group).most_common(1)[0]
    held = sum(1 for l in labels if l == label)
    return label != -1 and count >= 0.75 * n and held <= 1.25 * n


def transfer(s, X):
    """Squared symmetric transfer distance (mean of both directions) of every row of X
    ([n, 4] numpy array, x1 y1 x2 y2) to structure s of an answer; inf for other types."""
    import numpy as np
    x1 = np.c_[X[:, :2], np.ones(len(X))]
    x2 = np.c_[X[:, 2:], np.ones(len(X))]
    if s["type"] == "homography":
        H = np.array(s["params"]["h"]).reshape(3, 3)
    elif s["type"] == "affine":
        H = np.r_[np.array(s["params"]["a"]).reshape(2, 3), [[0, 0, 1]]]
    else:
        return np.full(len(X), np.inf)
    try:
        Hi = np.linalg.inv(H)
    except np.linalg.LinAlgError:
        return np.full(len(X), np.inf)
    p, q = x1 @ H.T, x2 @ Hi.T
    with np.errstate(all="ignore"):
        d = (((p[:, :2] / p[:, 2:] - X[:, 2:]) ** 2).sum(1) + ((q[:, :2] / q[:, 2:] - X[:, :2]) ** 2).sum(1)) / 2
    return np.where(np.isfinite(d), d, np.inf)
