#!/usr/bin/env python3
"""Two running servers (two builds, or one build started with and without a setting) fitting the
same AdelaideRMF pair in turn: the medians of their timing_ms (embed, refine and total), K chosen
by the model's card, and whether their labels agree.

Usage: research/alternate-latency.py PORT_A PORT_B [PAIR] [MODEL] [FITS]
       (defaults: bonhall, adelaide-homography, 12 fits each; ../shared/datasets needed)
"""
import json
import statistics
import sys
import urllib.request

port_a, port_b = sys.argv[1], sys.argv[2]
pair = sys.argv[3] if len(sys.argv) > 3 else "bonhall"
model = sys.argv[4] if len(sys.argv) > 4 else "adelaide-homography"
fits = int(sys.argv[5]) if len(sys.argv) > 5 else 12
data = json.load(open(f"../shared/datasets/adelaidermf/{pair}.json"))
body = json.dumps({"kind": "correspondences", "model": model, "points": data["points"],
                   "image_size": data["image_size"]}).encode()


def fit(port):
    req = urllib.request.Request(f"http://127.0.0.1:{port}/v1/fit", body,
                                 {"content-type": "application/json"})
    return json.load(urllib.request.urlopen(req))


answers = {port_a: [], port_b: []}
for port in answers:
    fit(port)  # warm-up
for _ in range(fits):
    for port in answers:
        answers[port].append(fit(port))
for port, rs in answers.items():
    embed, refine, total = (statistics.median(r["timing_ms"][t] for r in rs)
                            for t in ("embed", "refine", "total"))
    print(f"port {port}: {pair} with {model}, k {rs[0]['k']}: embed {embed:.1f} ms, refine {refine:.1f} ms, "
          f"total {total:.1f} ms (medians of {fits})")
print("same labels:", answers[port_a][0]["labels"] == answers[port_b][0]["labels"])
