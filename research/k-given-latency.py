"""timing_ms.refine of the AdelaideRMF homography pairs fitted with k given (the number of
structures), `adelaide-homography`, on two or more servers in turn: per pair the median of 3
fits after a warm-up, then the median over the pairs for each server (PERFORMANCE, the seeded
search given k). Needs running servers.

  python3 research/k-given-latency.py PORT_A PORT_B
"""
import glob, json, statistics as st, sys

import fitting

ports = sys.argv[1:]
per_pair = {p: [] for p in ports}
for path in sorted(glob.glob("../shared/datasets/adelaidermf/*.json")):
    d = json.load(open(path))
    if d["model_type"] != "homography":
        continue
    body = {"kind": "correspondences", "model": "adelaide-homography",
            "k": len(set(d["labels"]) - {0}), "points": d["points"], "image_size": d["image_size"]}
    times = {p: [] for p in ports}
    for rep in range(4):
        for p in ports:
            t = fitting.post(p, body)["timing_ms"]["refine"]
            if rep:
                times[p].append(t)
    for p in ports:
        per_pair[p].append(st.median(times[p]))
    print(d["name"], len(d["points"]), [round(st.median(times[p]), 1) for p in ports])
print("median over pairs", [round(st.median(per_pair[p]), 1) for p in ports])
