#!/usr/bin/env bash
# research/k-given.py on leave-one-out: each AdelaideRMF pair of MODEL's type fitted, with k =
# its number of structures, by the fold model that never saw it (served with the shipped card's
# serving settings: refinement, outliers, model family), then the mean. REFINE=0 fits
# without refinement and K=auto lets the card choose K, as in k-given.py.
# Usage: research/k-given-loo.sh [CV_RUN] [MODEL] [SERVER_BIN]
set -euo pipefail
cd "$(dirname "$0")/.."
run=${1:-runs/cv/adelaide-homography-mimi-twoview-ft10}
model=${2:-adelaide-homography}
bin=${3:-./target/release/multifit-server}
port=8411
out=$(mktemp)
for dir in "$run"/models/*/; do
  name=$(basename "$dir")
  tmp=$(mktemp -d)
  mkdir -p "$tmp/$model"
  cp "$dir"/* "$tmp/$model/"
  python3 - "$tmp/$model/model.json" "$model" <<'PY'
import json, sys
card = json.load(open(sys.argv[1])); shipped = json.load(open(f"models/{sys.argv[2]}/model.json"))
for key in ("name", "refine", "outliers", "geometry", "validated"):
    card[key] = shipped[key]
json.dump(card, open(sys.argv[1], "w"))
PY
  RAYON_NUM_THREADS=1 "$bin" --addr "127.0.0.1:$port" --models "$tmp" >/dev/null 2>&1 &
  pid=$!
  for _ in $(seq 100); do curl -sf "127.0.0.1:$port/health/ready" >/dev/null && break; sleep 0.1; done
  python3 research/k-given.py "$port" "$model" "$name" | tee -a "$out"
  kill "$pid"; wait "$pid" 2>/dev/null || true
  rm -rf "$tmp"
done
python3 - "$out" <<'PY'
import sys
rows = [line.split() for line in open(sys.argv[1])]
print("k kept", sum(r[1] == r[2] for r in rows), "/", len(rows),
      "mean error", round(sum(float(r[3]) for r in rows) / len(rows), 2))
PY
rm -f "$out"
