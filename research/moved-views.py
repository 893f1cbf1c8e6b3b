"""Every AdelaideRMF pair with its shipped model, refined, sent three ways: as given (no
image_size), moved by 1e7 px in both views, and with its second view scaled by 1.5 and two image
sizes. Prints how many answers of two servers are identical (labels and every structure
parameter), and, for each server, how many moved fits differ in labels or K from the pair as
given. Needs two servers on the shipped models (the same one twice to check a single build).

    python3 research/moved-views.py PORT_A PORT_B
"""
import glob, json, sys

from fitting import post

ports = sys.argv[1:3]
same = total = 0
moved_differs = {p: 0 for p in ports}
for path in sorted(glob.glob("../shared/datasets/adelaidermf/*.json")):
    d = json.load(open(path))
    model = "adelaide-homography" if d["model_type"] == "homography" else "adelaide-fundamental"
    w, h = d["image_size"]
    ways = [
        {"points": d["points"]},
        {"points": [[v + 1e7 for v in r] for r in d["points"]]},
        {"points": [[r[0], r[1], r[2] * 1.5, r[3] * 1.5] for r in d["points"]],
         "image_size": [[w, h], [w * 1.5, h * 1.5]]},
    ]
    answers = {p: [post(p, {"kind": "correspondences", "model": model, "refine": True, **body})
                   for body in ways] for p in ports}
    for a, b in zip(*answers.values()):
        total += 1
        same += (a["labels"], a["structures"]) == (b["labels"], b["structures"])
    for p, (given, moved, _) in answers.items():
        moved_differs[p] += (given["labels"], given["k"]) != (moved["labels"], moved["k"])
print(f"{same} of {total} answers identical between the two servers; moved 1e7 px, answers "
      f"that differ from the pair as given: "
      + ", ".join(f"port {p}: {n} of {total // 3}" for p, n in moved_differs.items()))
