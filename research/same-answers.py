"""Two servers, the same fits: every LCE set of the given gen-lce directories fitted by both, with
K chosen and with the true K; counts the fits whose labels agree and gives each server's mean
error (outliers, -1, as a group of their own). For a change that should not move any answer
(speed work): run the build before it on one port and the build after it on another.

  python3 research/same-answers.py PORT_A PORT_B DIR [DIR ...]
      e.g. DIR = runs/data/lce2-test (gen-lce --count 200 --seed 4 --scale 2) and runs/data/kc-out
      (gen-lce --count 100 --seed 7101 --scale 2 --outliers 0.2)"""
import glob, json, sys

from fitting import error, post

port_a, port_b, dirs = sys.argv[1], sys.argv[2], sys.argv[3:]
same = n = 0
errors = [0.0, 0.0]
for path in sorted(p for d in dirs for p in glob.glob(f"{d}/*.json")):
    s = json.load(open(path))
    truth = [l if l > 0 else -1 for l in s["labels"]]
    for given in ({}, {"k": s["num_models"]}):
        body = {"kind": "points2d", "points": s["points"], **given}
        answers = [post(port, body)["labels"] for port in (port_a, port_b)]
        same += answers[0] == answers[1]
        n += 1
        for i, labels in enumerate(answers):
            errors[i] += error(truth, [max(l, -1) for l in labels])
print(f"labels the same in {same} of {n} fits; mean error {100 * errors[0] / n:.2f} % "
      f"({port_a}) and {100 * errors[1] / n:.2f} % ({port_b})")
