"""Row order: the same sets with their rows shuffled, to measure how much an answer depends on
the order a caller sends its points in.

  python3 research/row-orders.py make SRC OUT SEED...   # OUT/s<SEED>/<name>.json, rows permuted
  python3 research/row-orders.py summary EVAL.json...   # known-K and SOD means of eval --json files

Each copy permutes every per-row list (points, labels, visible, ...) by one seeded permutation
per set (Python's random.Random("<seed>-<name>")).
"""
import glob, json, os, random, statistics as st, sys


def make(src, out, seeds):
    for s in seeds:
        d_out = f"{out}/s{s}"
        os.makedirs(d_out, exist_ok=True)
        for f in sorted(glob.glob(f"{src}/*.json")):
            d = json.load(open(f))
            n = len(d["points"])
            perm = list(range(n))
            random.Random(f"{s}-{d['name']}").shuffle(perm)
            for k, v in list(d.items()):
                if isinstance(v, list) and len(v) == n and k != "image_size":
                    d[k] = [v[i] for i in perm]
            json.dump(d, open(f"{d_out}/{os.path.basename(f)}", "w"))


def summary(files):
    known, sod = [], []
    for f in files:
        rows = json.load(open(f))["rows"]
        k = 100 * st.mean(r["known"]["error"] for r in rows)
        s = 100 * st.mean(r["sod"]["error"] for r in rows)
        right = sum(r["sod"]["k"] == r["k_true"] for r in rows)
        known.append(k), sod.append(s)
        print(f"{f}: known {k:.2f} SOD {s:.2f} (K right {right} of {len(rows)})")
    if len(files) > 1:
        print(f"mean over {len(files)}: known {st.mean(known):.2f} (sd {st.stdev(known):.2f}), "
              f"SOD {st.mean(sod):.2f} (sd {st.stdev(sod):.2f})")


if __name__ == "__main__":
    if sys.argv[1] == "make":
        make(sys.argv[2], sys.argv[3], [int(s) for s in sys.argv[4:]])
    else:
        summary(sys.argv[2:])
