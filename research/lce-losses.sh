#!/usr/bin/env bash
# The three losses on LCE at the stage-1 budget of the shipped recipe (scale 2, width 128,
# 12 blocks, neighbour offsets and graph aggregation over 16 points, 20 epochs over 4000 mixed +
# 4000 unmixed samples, lr 2e-3 cosine, seed 0, best epoch on the 100 validation samples), one
# thread each, side by side (about 64 minutes on 2 cores); then each model on the 500 validation
# samples and the scale-2 test sets, network alone and with mirror,rotate.
# The L2 run is stage 1 of scripts/train-models.sh lce, and reproduces it exactly.
# Usage: research/lce-losses.sh [LOSSES]   (default "l2 ce mimi"; models in runs/lce-loss-<loss>/,
# JSON in runs/lce-loss-evals/<loss>/)
set -euo pipefail
cd "$(dirname "$0")/.."
T=./target/release/multifit-train
cargo build --release --bin multifit-train
losses=${1:-l2 ce mimi}
gen() { [ -d "runs/data/$1" ] || $T gen-lce --out "runs/data/$1" --scale 2 "${@:2}"; }
gen lce2-train --count 4000 --seed 1 --variant mixed
gen lce2-unmixed-train --count 4000 --seed 2 --variant unmixed
gen lce2-val --count 100 --seed 3
gen lce2-val2 --count 400 --seed 81
gen lce2-test --count 200 --seed 4
gen lce2-unmixed-test --count 200 --seed 5 --variant unmixed
for loss in $losses; do
  RAYON_NUM_THREADS=1 $T train --name "lce-$loss" --out "runs/lce-loss-$loss/model" --run-dir "runs/lce-loss-$loss" \
    --data runs/data/lce2-train --data runs/data/lce2-unmixed-train --val runs/data/lce2-val \
    --loss "$loss" --embed-dim 6 --width 128 --depth 12 --neighbors 16 --graph-neighbors 16 --batch-size 16 \
    --schedule cosine --k-max 6 --lr 2e-3 --epochs 20 \
    --describe "Loss comparison at the stage-1 budget of lce: 4000 mixed + 4000 unmixed scale-2 samples (seeds 1, 2), loss $loss" \
    > "runs/lce-loss-$loss.log" 2>&1 &
done
wait
for loss in $losses; do
  m=runs/lce-loss-$loss/model o=runs/lce-loss-evals/$loss
  mkdir -p "$o"
  for sym in alone mirror-rotate; do
    s=(--test-symmetry); [ $sym = alone ] || s=(--test-symmetry mirror,rotate)
    $T eval --model "$m" --data runs/data/lce2-val --data runs/data/lce2-val2 --k-max 6 "${s[@]}" --json > "$o/val500-$sym.json"
    for d in lce2-test lce2-unmixed-test; do
      $T eval --model "$m" --data "runs/data/$d" --k-max 6 "${s[@]}" --json > "$o/$d-$sym.json"
    done
  done
done
python3 - $losses <<'PY'
import json, math, pathlib, sys
for loss in sys.argv[1:]:
    for f in sorted(pathlib.Path("runs/lce-loss-evals", loss).glob("*.json")):
        d = json.loads(f.read_text())
        k, s, h = (d["totals"][x] for x in ("known", "sod", "silhouette"))
        e = [r["known"]["error"] for r in d["rows"]]
        m = sum(e) / len(e)
        se = math.sqrt(sum((x - m) ** 2 for x in e) / (len(e) - 1) / len(e))
        print(f"{loss:5} {f.stem:30} known {100 * k['mean_error']:.2f} ± {100 * se:.2f} % / NMI {k['mean_nmi']:.3f} · "
              f"SOD {100 * s['mean_error']:.2f} % ({100 * s['k_correct']:.1f} % K right) · "
              f"silhouette {100 * h['mean_error']:.2f} % ({100 * h['k_correct']:.1f} %)")
PY
