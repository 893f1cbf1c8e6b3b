"""AdelaideRMF pairs with the second view as a camera of FACTOR times the resolution would see
it (its coordinates multiplied by FACTOR), fitted with known K by the shipped models: the pair
as-is, then with the first image's size, the second's, none, and each image's size
([[w, h], [FACTOR w, FACTOR h]]); mean error per model. Needs a running server (numpy).

  python3 research/two-cameras.py PORT [FACTOR]"""
import glob, json, statistics as st, sys
import numpy as np
from fitting import error, post

port = sys.argv[1]
factor = float(sys.argv[2]) if len(sys.argv) > 2 else 2.0
res = {}
for f in sorted(glob.glob('../shared/datasets/adelaidermf/*.json')):
    d = json.load(open(f))
    model, (w, h), k = 'adelaide-' + d['model_type'], d['image_size'], d['num_models']
    pts = d['points']
    truth = [l if l > 0 else -1 for l in d['labels']]
    big = [[p[0], p[1], p[2] * factor, p[3] * factor] for p in pts]
    cases = {'as-is': (pts, [w, h]), 'first image size': (big, [w, h]),
             'second image size': (big, [w * factor, h * factor]), 'no size': (big, None),
             'each image size': (big, [[w, h], [w * factor, h * factor]])}
    for name, (p, size) in cases.items():
        body = {"kind": "correspondences", "model": model, "points": p, "k": k}
        if size:
            body["image_size"] = size
        o = post(port, body)
        res.setdefault((model, name), []).append(100 * error(truth, o['labels']))
        if name != 'each image size':
            continue
        # Each homography maps view 1 into the second image's own pixels.
        for s in o.get('structures', []):
            if s['type'] != 'homography':
                continue
            idx = [i for i, l in enumerate(o['labels']) if l == s['label']]
            H = np.array(s['params']['h']).reshape(3, 3)
            y = H @ np.array([[p[i][0], p[i][1], 1.0] for i in idx]).T
            d2 = (y[:2] / y[2]).T - np.array([[p[i][2], p[i][3]] for i in idx])
            res.setdefault((model, 'median transfer (px, second image)'), []).append(
                float(np.median(np.sqrt((d2 ** 2).sum(1)))))
for (m, name), e in sorted(res.items()):
    print(f"{m:22s} {name:36s} {st.mean(e):6.2f} (mean of {len(e)})")
