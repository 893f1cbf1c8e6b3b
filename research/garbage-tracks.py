"""KT3DMoSeg frames 1..5 with a share of garbage tracks added: random walks that start anywhere in
the image and step by about twice a real track's median frame-to-frame motion (a tracker that
lost its feature and wanders). Each sequence is fitted by its fold model with k = its number of
motions, and scored twice under the best matching of groups: over every track (a garbage track is
right only when answered -1), and over the real tracks alone (how much the garbage moves them);
and, without garbage, how many real tracks the fits' warnings count as erratic (not read by
the network).

    python3 research/garbage-tracks.py PORT SHARE [DATA [FROM]]

PORT: a server on the fold models (`multifit-server --models runs/cv/kt-pretrained/models`,
which names each `fold-<sequence>`); SHARE: garbage tracks as a share of the real ones (0 for
none); DATA: default ../shared/datasets/kt3dmoseg_first5 (a set with `visible` masks, such as
../shared/datasets/kt3dmoseg, is read on its tracks seen in every frame); FROM (default 0): the
frame from which a garbage track wanders (at most the third from last), following a real track
(drawn at random) before it, as a tracker that loses its feature part-way. Standard library only."""
import glob, json, random, re, statistics, sys

from fitting import error, error_minus_one, post


def garbage(rows, share, width, height, rng, start=0):
    """`share` x len(rows) random walks over the frames of `rows` (at least one when share > 0),
    each following a real track up to frame `start` and wandering from there (from anywhere in
    the image when `start` is 0)."""
    frames = len(rows[0]) // 2
    start = min(start, frames - 3)
    steps = sorted(((r[-2] - r[0]) ** 2 + (r[-1] - r[1]) ** 2) ** 0.5 / (frames - 1) for r in rows)
    step = 2 * steps[len(steps) // 2] + 1
    walks = []
    for _ in range(max(1, round(share * len(rows))) if share > 0 else 0):
        if start > 0:
            walk = list(rng.choice(rows)[:2 * start])
            x, y = walk[-2], walk[-1]
            x, y = x + rng.gauss(0, step), y + rng.gauss(0, step)
        else:
            x, y, walk = rng.uniform(0, width), rng.uniform(0, height), []
        for _ in range(frames - start):
            walk += [x, y]
            x, y = x + rng.gauss(0, step), y + rng.gauss(0, step)
        walks.append(walk)
    return walks


def main():
    port, share = sys.argv[1], float(sys.argv[2])
    data = sys.argv[3] if len(sys.argv) > 3 else "../shared/datasets/kt3dmoseg_first5"
    start = int(sys.argv[4]) if len(sys.argv) > 4 else 0
    every, real, flagged, total = [], [], 0, 0
    for path in sorted(glob.glob(f"{data}/*.json")):
        seq = json.load(open(path))
        rows, truth = seq["points"], seq["labels"]
        if "visible" in seq:
            seen = [i for i, v in enumerate(seq["visible"]) if all(v)]
            rows, truth = [rows[i] for i in seen], [truth[i] for i in seen]
        width, height = seq["image_size"]
        walks = garbage(rows, share, width, height, random.Random(seq["name"]), start)
        answer = post(port, {"model": f"fold-{seq['name']}", "kind": "trajectories",
                             "points": rows + walks, "image_size": [width, height],
                             "k": len(set(truth))})
        labels = answer["labels"]
        for warning in answer["warnings"]:
            count = re.match(r"(\d+) of the tracks accelerate", warning)
            flagged += int(count.group(1)) if count else 0
        total += len(rows)
        every.append(error_minus_one(truth + [0] * len(walks), labels))
        real.append(error(truth, labels[:len(rows)]))
    print(f"garbage {100 * share:g} %: every track {100 * statistics.mean(every):.2f} %, "
          f"the real tracks {100 * statistics.mean(real):.2f} % ({len(every)} sequences)"
          + (f"; real tracks set apart as erratic: {flagged} of {total}" if share == 0 else ""))


if __name__ == "__main__":
    main()
