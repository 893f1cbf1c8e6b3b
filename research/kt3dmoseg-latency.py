#!/usr/bin/env python3
"""Latency of trajectory fits against a running server: the server's timing_ms of 4 fits after
one warm-up fit, k given and chosen by SOD.

Usage: research/kt3dmoseg-latency.py [port] [model]   (default 8080 and kt3dmoseg; start the
server with the shipped models first)
Body: the first 5 frames of KT3DMoSeg Seq095_Clip01 (565 tracks, the largest test clip) from
$MULTIFIT_DATA/kt3dmoseg_first5 (default ../shared/datasets).
"""
import json
import os
import pathlib
import sys
import urllib.request

port = sys.argv[1] if len(sys.argv) > 1 else "8080"
model = sys.argv[2] if len(sys.argv) > 2 else "kt3dmoseg"
data = pathlib.Path(os.environ.get("MULTIFIT_DATA", "../shared/datasets"))
f = json.loads((data / "kt3dmoseg_first5" / "Seq095_Clip01.json").read_text())
for k in [f["num_models"], None]:
    body = {"kind": "trajectories", "model": model, "points": f["points"],
            "image_size": f["image_size"]}
    if k is not None:
        body["k"] = k
    times = []
    for _ in range(5):
        req = urllib.request.Request(f"http://127.0.0.1:{port}/v1/fit", json.dumps(body).encode(),
                                     {"content-type": "application/json"})
        t = json.load(urllib.request.urlopen(req))["timing_ms"]
        times.append(f"{t['total']:.1f}/{t['embed']:.1f}/{t['cluster']:.1f}")
    print(f"N = {len(f['points'])}, k {'given' if k else 'by SOD'}: ms total/embed/cluster {' '.join(times[1:])}")
