"""Every AdelaideRMF pair with its shipped model (adelaide-homography on the homography pairs,
adelaide-fundamental on the fundamental ones), sent without image_size, k given and K chosen, as
given and moved by 3e7 and 2e8 px in both views: the mean error against the truth (outliers as -1
against label 0). Needs a server on the shipped models.

    python3 research/far-from-origin.py PORT
"""
import glob, json, sys, statistics
from fitting import post, error
port = sys.argv[1]
res = {}
for path in sorted(glob.glob('../shared/datasets/adelaidermf/*.json')):
    d = json.load(open(path))
    model = 'adelaide-homography' if d['model_type'] == 'homography' else 'adelaide-fundamental'
    k = len(set(d['labels']) - {0})
    for mode, given in (('k', {'k': k}), ('auto', {})):
        for off in (0.0, 3e7, 2e8):
            pts = [[v + off for v in r] for r in d['points']]
            a = post(port, {'kind': 'correspondences', 'model': model, 'points': pts, **given})
            res.setdefault((model, mode, off), []).append(error(d['labels'], [max(l, -1) for l in a['labels']]))
for (model, mode, off), e in sorted(res.items()):
    print(f'{model:22s} {mode:4s} offset {off:.0e}: mean error {100*statistics.mean(e):.2f} % ({len(e)} pairs)')
