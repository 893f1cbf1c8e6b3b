"""KT3DMoSeg frames 1..5 with a share of garbage tracks added: random walks that start anywhere in
the image and step by about twice a real track's median frame-to-frame motion (a tracker that
lost its feature and wanders). Each sequence is fitted by its fold model with k = its number of
motions, and scored twice under the best matching of groups: over every track (a garbage track is
right only when answered -1), and over the real tracks alone (how much the garbage moves them);
and, without garbage, how many real tracks the fits' warnings count as erratic (not read by
the network).

    python3 research/garbage-tracks.py PORT SHARE [DATA [FROM [partly]]]

PORT: a server on the fold models (`multifit-server --models runs/cv/kt-pretrained/models`,
which names each `fold-<sequence>`); SHARE: garbage tracks as a share of the real ones (0 for
none); DATA: default ../shared/datasets/kt3dmoseg_first5 (a set with `visible` masks, such as
../shared/datasets/kt3dmoseg, is read on its tracks seen in every frame); FROM (default 0): the
frame from which a garbage track wanders (at most the third from last), following a real track
(drawn at random) before it, as a tracker that loses its feature part-way. With `partly` (a set
with `visible` masks), every track is sent with its mask, and each garbage track is seen in one
run of 10 frames (or all, if fewer) at a random place, wandering there. Standard library only."""
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
    partly = len(sys.argv) > 5 and sys.argv[5] == "partly"
    every, real, flagged, total = [], [], 0, 0
    for path in sorted(glob.glob(f"{data}/*.json")):
        seq = json.load(open(path))
        rows, truth, visible = seq["points"], seq["labels"], None
        if "visible" in seq and not partly:
            seen = [i for i, v in enumerate(seq["visible"]) if all(v)]
            rows, truth = [rows[i] for i in seen], [truth[i] for i in seen]
        elif partly:
            visible = [[int(bool(f)) for f in v] for v in seq["visible"]]
        width, height = seq["image_size"]
        rng = random.Random(seq["name"])
        if partly:
            complete = [r for r, v in zip(rows, visible) if all(v)]
            frames = len(visible[0])
            run = min(10, frames)
            walks, masks = [], []
            for walk in garbage(complete, share, width, height, rng):
                at = rng.randrange(frames - run + 1)
                mask = [int(at <= f < at + run) for f in range(frames)]
                walks.append([v if mask[j // 2] else 0.0 for j, v in enumerate(walk)])
                masks.append(mask)
            visible = visible + masks
        else:
            walks = garbage(rows, share, width, height, rng, start)
        body = {"model": f"fold-{seq['name']}", "kind": "trajectories",
                "points": rows + walks, "image_size": [width, height], "k": len(set(truth))}
        if visible is not None:
            body["visible"] = visible
        answer = post(port, body)
        labels = answer["labels"]
        for warning in answer["warnings"]:
            count = re.match(r"(\d+) of the (?:partly seen )?tracks accelerate", warning)
            flagged += int(count.group(1)) if count else 0
        total += len(rows)
        every.append(error_minus_one(truth + [0] * len(walks), labels))
        real.append(error(truth, labels[:len(rows)]))
    print(f"garbage {100 * share:g} %: every track {100 * statistics.mean(every):.2f} %, "
          f"the real tracks {100 * statistics.mean(real):.2f} % ({len(every)} sequences)"
          + (f"; real tracks set apart as erratic: {flagged} of {total}" if share == 0 else ""))


if __name__ == "__main__":
    main()
