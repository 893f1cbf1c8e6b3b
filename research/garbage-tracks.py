"""KT3DMoSeg frames 1..5 with a share of garbage tracks added: random walks that start anywhere in
the image and step by about twice a real track's median frame-to-frame motion (a tracker that
lost its feature and wanders). Each sequence is fitted by its fold model with k = its number of
motions, and scored twice under the best matching of groups: over every track (a garbage track is
right only when answered -1), and over the real tracks alone (how much the garbage moves them);
and, without garbage, how many real tracks the fits' warnings count as erratic (not read by
the network).

    python3 research/garbage-tracks.py PORT SHARE [DATA]

PORT: a server on the fold models (`multifit-server --models runs/cv/kt-pretrained/models`,
which names each `fold-<sequence>`); SHARE: garbage tracks as a share of the real ones (0 for
none); DATA: default ../shared/datasets/kt3dmoseg_first5. Standard library only."""
import glob, json, random, re, statistics, sys

from fitting import error, error_minus_one, post


def garbage(rows, share, width, height, rng):
    """`share` x len(rows) random walks over the frames of `rows` (at least one when share > 0)."""
    frames = len(rows[0]) // 2
    steps = sorted(((r[-2] - r[0]) ** 2 + (r[-1] - r[1]) ** 2) ** 0.5 / (frames - 1) for r in rows)
    step = 2 * steps[len(steps) // 2] + 1
    walks = []
    for _ in range(max(1, round(share * len(rows))) if share > 0 else 0):
        x, y, walk = rng.uniform(0, width), rng.uniform(0, height), []
        for _ in range(frames):
            walk += [x, y]
            x, y = x + rng.gauss(0, step), y + rng.gauss(0, step)
        walks.append(walk)
    return walks


def main():
    port, share = sys.argv[1], float(sys.argv[2])
    data = sys.argv[3] if len(sys.argv) > 3 else "../shared/datasets/kt3dmoseg_first5"
    every, real, flagged, total = [], [], 0, 0
    for path in sorted(glob.glob(f"{data}/*.json")):
        seq = json.load(open(path))
        rows, truth = seq["points"], seq["labels"]
        width, height = seq["image_size"]
        walks = garbage(rows, share, width, height, random.Random(seq["name"]))
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
