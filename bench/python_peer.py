#!/usr/bin/env python3
"""The multifit fit pipeline in numpy + scikit-learn: the Python peer of `POST /v1/fit`.

It does the same work as the Rust server for one point set:

1. normalise the raw rows as the model card says (`src/data/points.rs`):
   - `image_frame` (correspondences, trajectories): every (x, y) pair becomes
     `(p - image centre) / (max(w, h) / 2)`; without an image size the bounding box of all pairs
     stands in for the image;
   - `centroid_unit_rms` (points2d): centred on the mean, scaled to unit RMS distance;
   Tracks of another length than the model's are first read at the card's `frames`
   (`src/data/frames.rs`): for `windows`, one set per window of consecutive frames, each
   normalised, embedded and set side by side (scaled by 1/sqrt(windows));
2. optionally append the offsets to the `neighbors` nearest points (`src/data/features.rs`);
3. run the embedding network (`src/model.rs`) in float32 with the shipped weights:
   `x @ W + b` (weights are stored `[d_in, d_out]`), then `depth` residual blocks
   `h = relu(BN?(CN(x @ W1 [+ mean of (x @ G) over the point's graph neighbourhood])));
   h = relu(BN?(CN(h @ W2))); x = x + h`, then the output Linear and a per-row L2
   normalisation. Context Normalization (CN) standardises each channel over the points with the
   biased variance and `card.architecture.cn_epsilon`; the graph neighbourhood (graph models) is
   the point and its `graph_neighbors - 1` nearest others in the normalised coordinates;
4. cluster the embeddings (`src/cluster/`) with scikit-learn: `KMeans(k-means++, n_init=4)`
   for K = 1..k_max (k_max + 1 for SOD, capped at N), the residual r(K) = inertia, and K chosen
   by the mean silhouette (`sklearn.metrics.silhouette_score`, on a seeded sample of 3000 points
   beyond 3000, like the server) or by the SOD of log r(K); K = 1 when r(1)/N < 0.01.

The peer has no geometric refinement (the server's stage 5): where the server refines by
default (tracks of 15 frames or more for `kt3dmoseg` and `motion`, `lce`, `adelaide-homography`), it does
more work than the peer, and its labels may differ where refinement moved points.

The random streams differ from the server's (ChaCha8 there, numpy's Mersenne Twister here), so the
k-means restarts start from different seeds: labels and K usually agree but need not be identical.
The embeddings are deterministic and agree to float32 rounding (see `--compare-url`).

The weights are read with a small hand-written safetensors parser (8-byte little-endian header
length, JSON header, raw little-endian data), so nothing beyond numpy and scikit-learn is needed.

Usage:
    python3 bench/python_peer.py --model models/adelaide-homography \\
        --input ../shared/datasets/adelaidermf/bonhall.json --selection silhouette --seed 0
    # also fit through a running server and compare embeddings and labels:
    python3 bench/python_peer.py ... --compare-url http://127.0.0.1:8080
"""

from __future__ import annotations

import argparse
import json
import struct
import sys
import time
from pathlib import Path

import numpy as np
from sklearn.cluster import KMeans
from sklearn.metrics import silhouette_score

# Same constants as src/cluster/.
RESTARTS = 4
MAX_ITER = 100
SINGLE_SPREAD = 0.01
SILHOUETTE_EXACT_MAX = 3000
# burn's BatchNormConfig default epsilon (only used when a card has batch_norm: true).
BN_EPSILON = 1e-5

_SAFETENSORS_DTYPES = {
    "F64": "<f8",
    "F32": "<f4",
    "F16": "<f2",
    "I64": "<i8",
    "I32": "<i4",
    "U8": "u1",
}


def load_safetensors(path: Path) -> dict[str, np.ndarray]:
    """Reads every tensor of a safetensors file into a dict of numpy arrays."""
    raw = Path(path).read_bytes()
    if len(raw) < 8:
        raise ValueError(f"{path}: too short for a safetensors file")
    (header_len,) = struct.unpack("<Q", raw[:8])
    if 8 + header_len > len(raw):
        raise ValueError(f"{path}: header length {header_len} exceeds the file")
    header = json.loads(raw[8 : 8 + header_len].decode("utf-8"))
    data = memoryview(raw)[8 + header_len :]
    tensors = {}
    for name, info in header.items():
        if name == "__metadata__":
            continue
        dtype = _SAFETENSORS_DTYPES.get(info["dtype"])
        if dtype is None:
            raise ValueError(f"{path}: tensor {name}: unsupported dtype {info['dtype']}")
        start, end = info["data_offsets"]
        shape = tuple(info["shape"])
        arr = np.frombuffer(data[start:end], dtype=dtype)
        if arr.size != int(np.prod(shape, dtype=np.int64)):
            raise ValueError(f"{path}: tensor {name}: {arr.size} values for shape {shape}")
        tensors[name] = arr.reshape(shape)
    return tensors


class Model:
    """A shipped model directory: `model.json` card + `weights.safetensors`."""

    def __init__(self, directory: str | Path):
        directory = Path(directory)
        self.card = json.loads((directory / "model.json").read_text())
        arch = self.card["architecture"]
        self.name = self.card["name"]
        self.kind = self.card["kind"]
        self.input_dim = int(arch["input_dim"])
        self.neighbors = int(arch.get("neighbors", 0))
        self.eps = np.float32(arch["cn_epsilon"])
        self.embed_dim = int(arch["embed_dim"])
        self.graph_neighbors = int(arch.get("graph_neighbors", 0))
        self.frames = self.card.get("frames", "spread")
        t = load_safetensors(directory / "weights.safetensors")
        used = set()

        def take(key: str) -> np.ndarray:
            if key not in t:
                raise KeyError(f"{directory}: weights lack tensor {key!r}")
            used.add(key)
            return np.ascontiguousarray(t[key], dtype=np.float32)

        feature_dim = self.input_dim * (1 + self.neighbors)
        self.w_in, self.b_in = take("input.weight"), take("input.bias")
        if self.w_in.shape != (feature_dim, arch["width"]):
            raise ValueError(f"{directory}: input.weight is {self.w_in.shape}, the card says "
                             f"({feature_dim}, {arch['width']})")
        self.blocks = []
        for i in range(int(arch["depth"])):
            block = {"w1": take(f"blocks.{i}.l1.weight"), "w2": take(f"blocks.{i}.l2.weight")}
            if self.graph_neighbors > 0:
                block["g"] = take(f"blocks.{i}.agg.weight")
            if arch["batch_norm"]:
                # burn's BatchNorm in inference: (x - running_mean) / sqrt(running_var + eps)
                # * gamma + beta. No shipped model uses it, so this path is untested against the
                # server.
                for bn in ("bn1", "bn2"):
                    p = f"blocks.{i}.{bn}."
                    block[bn] = tuple(take(p + k) for k in
                                      ("gamma", "beta", "running_mean", "running_var"))
            self.blocks.append(block)
        self.w_out, self.b_out = take("output.weight"), take("output.bias")
        left = set(t) - used
        if left:
            raise ValueError(f"{directory}: unexpected tensors {sorted(left)}")

    # -- 1. normalisation -------------------------------------------------------------------------

    def normalise(self, points: np.ndarray, image_size=None) -> np.ndarray:
        """Raw rows [n, d] (pixels or world units) -> normalised float32 rows [n, d]."""
        pts = np.asarray(points, dtype=np.float64)
        pairs = pts.reshape(-1, 2)
        norm = self.card["normalization"]
        if norm == "centroid_unit_rms":
            c = pairs.mean(axis=0)
            scale = np.sqrt(((pairs - c) ** 2).sum(axis=1).mean())
        elif norm == "image_frame":
            if image_size is not None:
                w, h = float(image_size[0]), float(image_size[1])
                c = np.array([w / 2.0, h / 2.0])
                scale = max(w, h) / 2.0
            else:
                lo, hi = pairs.min(axis=0), pairs.max(axis=0)
                c = (lo + hi) / 2.0
                scale = (hi - lo).max() / 2.0
        else:
            raise ValueError(f"unknown normalization {norm!r}")
        inv = 1.0 / scale if scale > 0 else 1.0
        return ((pairs - c) * inv).astype(np.float32).reshape(pts.shape)

    # -- 2. neighbour features --------------------------------------------------------------------

    def features(self, x: np.ndarray) -> np.ndarray:
        """[n, d] -> [n, d * (1 + neighbors)]: each point, then offsets to its nearest others,
        nearest first, ties by index; zeros where fewer than `neighbors` other points exist."""
        k = self.neighbors
        if k == 0:
            return x
        n, d = x.shape
        take = min(k, n - 1)
        order = nearest(x, take)
        offsets = x[order] - x[:, None, :]  # [n, take, d]
        out = np.zeros((n, d * (1 + k)), dtype=np.float32)
        out[:, :d] = x
        out[:, d : d * (1 + take)] = offsets.reshape(n, take * d)
        return out

    # -- 3. the network ---------------------------------------------------------------------------

    def _cn(self, h: np.ndarray) -> np.ndarray:
        mean = h.mean(axis=0, keepdims=True)
        var = ((h - mean) ** 2).mean(axis=0, keepdims=True)  # biased variance
        return (h - mean) / np.sqrt(var + self.eps)

    @staticmethod
    def _bn(h: np.ndarray, params) -> np.ndarray:
        gamma, beta, mean, var = params
        return (h - mean) / np.sqrt(var + np.float32(BN_EPSILON)) * gamma + beta

    def graph(self, coords: np.ndarray) -> np.ndarray | None:
        """Normalised points [n, d] -> [n, graph_neighbors]: each point's graph neighbourhood,
        itself first, then its nearest others (itself again where fewer exist)."""
        k = self.graph_neighbors
        if k == 0:
            return None
        n = len(coords)
        take = min(k - 1, n - 1)
        out = np.repeat(np.arange(n)[:, None], k, axis=1)
        if take > 0:
            out[:, 1 : 1 + take] = nearest(coords, take)
        return out

    def embed(self, features: np.ndarray) -> np.ndarray:
        """Network input [n, feature_dim] float32 -> unit embeddings [n, embed_dim] float32."""
        x = features.astype(np.float32, copy=False) @ self.w_in + self.b_in
        graph = self.graph(features[:, : self.input_dim])
        for blk in self.blocks:
            u = x @ blk["w1"]
            if graph is not None:
                # The mean of G x over each point's neighbourhood (itself included).
                u = u + (x @ blk["g"])[graph].mean(axis=1)
            h = self._cn(u)
            if "bn1" in blk:
                h = self._bn(h, blk["bn1"])
            h = np.maximum(h, 0)
            h = self._cn(h @ blk["w2"])
            if "bn2" in blk:
                h = self._bn(h, blk["bn2"])
            x = x + np.maximum(h, 0)
        z = x @ self.w_out + self.b_out
        return z / np.maximum(np.linalg.norm(z, axis=1, keepdims=True), np.float32(1e-12))

    # -- 1b. frames (trajectories) ----------------------------------------------------------------

    def windows(self, points: np.ndarray) -> list[np.ndarray]:
        """Tracks [n, 2F] -> one [n, input_dim] set per window the network reads
        (`src/data/frames.rs`): the input itself when it has the model's width or is not
        trajectories."""
        if self.kind != "trajectories" or points.shape[1] == self.input_dim:
            return [points]
        frames, target = points.shape[1] // 2, self.input_dim // 2
        return [read_at(points, t) for t in frame_windows(self.frames, frames, target)]

    # -- the whole pipeline -----------------------------------------------------------------------

    def fit(self, points, image_size=None, k=None, k_max=None, selection=None, seed=0) -> dict:
        """Normalise, embed and cluster one point set; an answer shaped like the server's."""
        t0 = time.perf_counter()
        windows = self.windows(np.asarray(points, dtype=np.float64))
        blocks = []
        for read in windows:
            x = self.normalise(read, image_size)
            if x.ndim != 2 or x.shape[1] != self.input_dim:
                raise ValueError(f"model {self.name} takes rows of {self.input_dim} values")
            blocks.append(self.embed(self.features(x)))
        # Windows side by side, scaled so that every row keeps unit length.
        z = np.hstack(blocks) / np.float32(np.sqrt(len(blocks))) if len(blocks) > 1 else blocks[0]
        t1 = time.perf_counter()
        result = cluster(
            z,
            k=k,
            k_max=self.card["k_max"] if k_max is None else k_max,
            selection=self.card["selection"] if selection is None else selection,
            seed=seed,
        )
        t2 = time.perf_counter()
        result["embeddings"] = z
        result["timing_ms"] = {
            "embed": (t1 - t0) * 1e3,
            "cluster": (t2 - t1) * 1e3,
            "total": (t2 - t0) * 1e3,
        }
        return result


def nearest(x: np.ndarray, take: int) -> np.ndarray:
    """Points [n, d] float32 -> [n, take]: each point's nearest others, nearest first, ties by
    index (`src/data/features.rs`)."""
    d2 = ((x[:, None, :] - x[None, :, :]) ** 2).sum(axis=2)  # float32, like the server
    np.fill_diagonal(d2, np.inf)
    return np.argsort(d2, axis=1, kind="stable")[:, :take]  # stable sort: ties by index


MAX_WINDOWS = 4  # src/data/frames.rs


def frame_times(sampling: str, frames: int, target: int) -> list[float]:
    """The times of `target` frames on an axis of `frames` (`FrameSampling::times`)."""
    if sampling == "spread" or frames < target:
        if target == 1:
            return [0.0]
        step = (frames - 1) / (target - 1)
        return [i * step for i in range(target)]
    return [float(i) for i in range(target)]


def frame_windows(sampling: str, frames: int, target: int) -> list[list[float]]:
    """The times of each window read (`FrameSampling::windows`)."""
    if sampling != "windows" or frames <= target:
        return [frame_times(sampling, frames, target)]
    count = min(-(-frames // target), MAX_WINDOWS)
    span = frames - target
    # Python's round() rounds halves to even; Rust's f64::round rounds them away from zero.
    starts = [np.floor(w * span / (count - 1) + 0.5) for w in range(count)]
    return [[s + i for i in range(target)] for s in starts]


def read_at(points: np.ndarray, times: list[float]) -> np.ndarray:
    """Tracks [n, 2F] -> [n, 2 len(times)], linearly interpolated at fractional times."""
    frames = points.shape[1] // 2
    xy = points.reshape(len(points), frames, 2)
    out = []
    for t in times:
        lo = min(int(np.floor(t)), frames - 1)
        hi = min(lo + 1, frames - 1)
        w = t - lo
        out.append(xy[:, lo] if w == 0.0 else xy[:, lo] + w * (xy[:, hi] - xy[:, lo]))
    return np.stack(out, axis=1).reshape(len(points), 2 * len(times))


# -- 4. clustering and the choice of K ------------------------------------------------------------


def kmeans(z: np.ndarray, k: int, seed: int) -> KMeans:
    """k-means++ seeding, 4 restarts, Lloyd until the assignments stop changing (tol = 0), the
    lowest residual kept: the server's `cluster::kmeans`."""
    return KMeans(
        n_clusters=k, init="k-means++", n_init=RESTARTS, max_iter=MAX_ITER, tol=0.0,
        algorithm="lloyd", random_state=seed,
    ).fit(z)


def sod_scores(residuals: list[tuple[int, float]]) -> list[tuple[int, float]]:
    """sod(K) = l(K-1) + l(K+1) - 2 l(K) with l = log r, for the inner points of the curve."""
    floor = (residuals[0][1] if residuals else 0.0) * 1e-9 + 1e-12
    l = [np.log(r + floor) for _, r in residuals]
    return [(residuals[i][0], float(l[i - 1] + l[i + 1] - 2 * l[i]))
            for i in range(1, len(residuals) - 1)]


def canonical(labels: np.ndarray) -> tuple[list[int], list[int]]:
    """Relabels clusters by first appearance in input order; returns (labels, sizes)."""
    mapping: dict[int, int] = {}
    out = [mapping.setdefault(int(l), len(mapping)) for l in labels]
    sizes = [0] * len(mapping)
    for l in out:
        sizes[l] += 1
    return out, sizes


def cluster(z: np.ndarray, k=None, k_max=8, selection="sod", seed=0) -> dict:
    """The server's `cluster::cluster` with scikit-learn doing k-means and the silhouette."""
    n = len(z)
    if k is not None:
        if not 1 <= k <= n:
            raise ValueError(f"k = {k} must be between 1 and {n}")
        chosen = kmeans(z, k, seed)
        residuals, scores, selection = [(k, float(chosen.inertia_))], [], "fixed"
    else:
        k_max = min(k_max, n)
        top = min(k_max + 1, n) if selection == "sod" else k_max
        runs = [kmeans(z, kk, seed) for kk in range(1, top + 1)]
        residuals = [(i + 1, float(r.inertia_)) for i, r in enumerate(runs)]
        if selection == "sod":
            scores = [s for s in sod_scores(residuals) if s[0] <= k_max]
        elif selection == "silhouette":
            sample = SILHOUETTE_EXACT_MAX if n > SILHOUETTE_EXACT_MAX else None
            scores = [(kk, float(silhouette_score(z, runs[kk - 1].labels_,
                                                  sample_size=sample, random_state=seed)))
                      for kk in range(2, k_max + 1)]
        else:
            raise ValueError(f"selection {selection!r} is not sod or silhouette")
        if k_max == 1 or residuals[0][1] / n < SINGLE_SPREAD:
            best = 1
        elif scores:
            best = max(scores, key=lambda s: s[1])[0]  # first K on ties, like the server
        else:
            best = k_max
        chosen = runs[best - 1]
    labels, sizes = canonical(chosen.labels_)
    return {
        "labels": labels,
        "k": len(sizes),
        "selection": selection,
        "residuals": [{"k": kk, "r": r} for kk, r in residuals],
        "scores": [{"k": kk, "score": s} for kk, s in scores],
        "cluster_sizes": sizes,
    }


# -- command line ---------------------------------------------------------------------------------


def _post_json(url: str, body: dict) -> dict:
    import urllib.request

    req = urllib.request.Request(url.rstrip("/") + "/v1/fit", data=json.dumps(body).encode(),
                                 headers={"content-type": "application/json"})
    with urllib.request.urlopen(req, timeout=120) as r:
        return json.loads(r.read())


def compare_with_server(model: Model, answer: dict, server: dict) -> dict:
    """Agreement between this peer's answer and the server's (which must carry embeddings)."""
    from sklearn.metrics import adjusted_rand_score

    zs = np.asarray(server["embeddings"], dtype=np.float64)
    zp = answer["embeddings"].astype(np.float64)
    diff = np.abs(zs - zp)
    # Residual curves: relative difference per K.
    rel = [abs(a["r"] - b["r"]) / max(b["r"], 1e-12)
           for a, b in zip(answer["residuals"], server["residuals"])]
    return {
        "embed_max_abs_diff": float(diff.max()),
        "embed_mean_abs_diff": float(diff.mean()),
        "k_peer": answer["k"],
        "k_server": server["k"],
        "labels_ari": float(adjusted_rand_score(server["labels"], answer["labels"])),
        "residual_max_rel_diff": float(max(rel)) if rel else 0.0,
    }


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--model", default="models/adelaide-homography", help="model directory")
    ap.add_argument("--input", required=True,
                    help="JSON with 'points' (and optionally 'image_size'), e.g. a dataset file")
    ap.add_argument("--k", type=int)
    ap.add_argument("--k-max", type=int)
    ap.add_argument("--selection", choices=["sod", "silhouette"])
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--no-image-size", action="store_true",
                    help="ignore the input's image_size (bounding-box normalisation)")
    ap.add_argument("--compare-url",
                    help="also fit through this running server and report the agreement")
    args = ap.parse_args()

    model = Model(args.model)
    data = json.loads(Path(args.input).read_text())
    points = np.asarray(data["points"], dtype=np.float64)
    image = None if args.no_image_size else data.get("image_size")
    answer = model.fit(points, image, k=args.k, k_max=args.k_max, selection=args.selection,
                       seed=args.seed)
    out = {key: answer[key] for key in ("k", "selection", "cluster_sizes", "scores", "timing_ms")}
    out["n"] = len(points)
    if args.compare_url:
        body = {"kind": model.kind, "model": model.name, "points": points.tolist(),
                "seed": args.seed, "return_embeddings": True}
        for key, val in (("image_size", image), ("k", args.k), ("k_max", args.k_max),
                         ("selection", args.selection)):
            if val is not None:
                body[key] = val
        out["agreement"] = compare_with_server(model, answer, _post_json(args.compare_url, body))
    json.dump(out, sys.stdout, indent=1)
    print()
    return 0


if __name__ == "__main__":
    sys.exit(main())
