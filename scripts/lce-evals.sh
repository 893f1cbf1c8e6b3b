#!/usr/bin/env bash
# Every LCE evaluation in docs/RESULTS.md for one model: validation, the scale-2 and unit-scale
# test sets, mixed and unmixed, with the card's test symmetries and with the network alone; then
# the LCE-Unmixed by-type table. JSON per set in runs/lce-evals/<model name>/.
# Usage: scripts/lce-evals.sh [MODEL_DIR] [--record]   (default models/lce; --record stores the
# served figures, test symmetries included, in the card's metrics)
set -euo pipefail
cd "$(dirname "$0")/.."
m=${1:-models/lce}; rec=${2:-}
T=./target/release/multifit-train
cargo build --release --bin multifit-train   # as train-models.sh: never evaluate with a stale binary
gen() { [ -d "runs/data/$1" ] || $T gen-lce --out "runs/data/$1" "${@:2}"; }
gen lce2-val --count 100 --seed 3 --scale 2
gen lce2-val2 --count 400 --seed 81 --scale 2
gen lce2-test --count 200 --seed 4 --scale 2
gen lce2-unmixed-test --count 200 --seed 5 --variant unmixed --scale 2
gen lce-test --count 200 --seed 4
gen lce-unmixed-test --count 200 --seed 5 --variant unmixed
o=runs/lce-evals/$(basename "$m"); mkdir -p "$o"
declare -A metric=([lce2-val]=lce_val_error [lce2-val2]=lce_val2_error [lce2-test]=lce_test_error
  [lce2-unmixed-test]=lce_unmixed_test_error [lce-test]=lce_scale1_test_error
  [lce-unmixed-test]=lce_scale1_unmixed_test_error)
for d in lce2-val lce2-val2 lce2-test lce2-unmixed-test lce-test lce-unmixed-test; do
  r=(); [ "$rec" = --record ] && r=(--record "${metric[$d]}")
  $T eval --model "$m" --data "runs/data/$d" --k-max 6 --json "${r[@]}" > "$o/$d.json"
  $T eval --model "$m" --data "runs/data/$d" --k-max 6 --test-symmetry --json > "$o/$d-alone.json"
done
python3 scripts/lce-by-type.py "$o/lce2-unmixed-test.json" runs/data/lce2-unmixed-test
python3 - "$o" <<'PY'
import json, pathlib, sys
for f in sorted(pathlib.Path(sys.argv[1]).glob("*.json")):
    t = json.loads(f.read_text())["totals"]
    k, s, h = t["known"], t["sod"], t["silhouette"]
    print(f"{f.stem:24} known {100 * k['mean_error']:.2f} % / NMI {k['mean_nmi']:.3f} · "
          f"SOD {100 * s['mean_error']:.2f} % ({100 * s['k_correct']:.1f} % K right) · "
          f"silhouette {100 * h['mean_error']:.2f} % ({100 * h['k_correct']:.1f} %)")
PY
