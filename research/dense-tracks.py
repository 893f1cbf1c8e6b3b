"""Dense track sets: three rigid motions (a wide background, two small objects) seen by a moving
pinhole camera at 1920 x 1080, posted with k = 3 at several densities; accuracy under the best
matching of groups (outliers, -1, as a group of their own). Needs a running server.

  python3 research/dense-tracks.py PORT MODEL [SEEDS]     e.g. SEEDS=0,1,2 (default)

Prints one line per frame count and density and the mean over the sets of 1260 tracks or more."""
import itertools, json, sys, urllib.request
import numpy as np

port, model = sys.argv[1], sys.argv[2]
seeds = [int(s) for s in (sys.argv[3] if len(sys.argv) > 3 else "0,1,2").split(",")]


def rot(axis, angle):
    a = np.asarray(axis, float) / np.linalg.norm(axis)
    k = np.array([[0, -a[2], a[1]], [a[2], 0, -a[0]], [-a[1], a[0], 0]])
    return np.eye(3) + np.sin(angle) * k + (1 - np.cos(angle)) * k @ k


def scene(frames, rng, background, objects, w=1920, h=1080, f=1200.0, noise=0.5):
    """Tracks [n, 2F] and labels: a background box and two small moving boxes."""
    cam = np.array([[f, 0, w / 2], [0, f, h / 2], [0, 0, 1]])
    bodies = [
        (np.c_[rng.uniform(-8, 8, background), rng.uniform(-4, 4, background),
               rng.uniform(15, 30, background)], np.zeros(3), 0.0),
        (np.c_[rng.uniform(-1, 1, objects) - 3, rng.uniform(-1, 1, objects),
               rng.uniform(-1, 1, objects) + 12], np.array([2.0, 0.3, 0]), 0.4),
        (np.c_[rng.uniform(-1, 1, objects) + 3, rng.uniform(-1, 1, objects),
               rng.uniform(-1, 1, objects) + 14], np.array([-1.5, -0.8, 1.0]), -0.5),
    ]
    tracks, labels = [], []
    for label, (x, v, spin) in enumerate(bodies):
        c = x.mean(0)
        rows = []
        for t in range(frames):
            s = t / (frames - 1)
            xt = (x - c) @ rot([0.2, 1, 0.1], spin * s).T + c + v * s
            xc = (xt - np.array([0.5, 0, 0.5]) * s) @ rot([0, 1, 0], 0.05 * s)
            p = (cam @ xc.T).T
            rows.append(p[:, :2] / p[:, 2:])
        tracks.append(np.stack(rows, 1).reshape(len(x), 2 * frames))
        labels += [label] * len(x)
    tracks = np.vstack(tracks)
    return tracks + rng.normal(0, noise, tracks.shape), np.array(labels)


def accuracy(truth, labels):
    ks, ts = sorted(set(labels)), sorted(set(truth))
    pairs = list(zip(labels, truth))
    count = {p: pairs.count(p) for p in set(pairs)}
    best = max(sum(count.get((a, b), 0) for a, b in zip(ks, perm) if b is not None)
               for perm in itertools.permutations(ts + [None] * max(0, len(ks) - len(ts)), len(ks)))
    return best / len(truth)


def post(body):
    req = urllib.request.Request(f"http://127.0.0.1:{port}/v1/fit", data=json.dumps(body).encode(),
                                 headers={"content-type": "application/json"})
    return json.load(urllib.request.urlopen(req))


dense = []
for frames in (5, 20):
    for mult in (1, 3.5, 5, 7):
        accs = []
        for seed in seeds:
            rng = np.random.default_rng(1000 * seed + 10 * frames + int(2 * mult))
            t, truth = scene(frames, rng, int(200 * mult), int(80 * mult))
            r = post({"kind": "trajectories", "model": model, "points": t.tolist(),
                      "image_size": [1920, 1080], "k": 3})
            accs.append(accuracy(list(truth), r["labels"]))
        n = len(t)
        if n >= 1260:
            dense += accs
        print(f"F {frames:>2}  tracks {n:>5}  accuracy {np.mean(accs):.4f}  ({' '.join(f'{a:.3f}' for a in accs)})")
print(f"mean accuracy, 1260 tracks or more: {np.mean(dense):.4f}")
