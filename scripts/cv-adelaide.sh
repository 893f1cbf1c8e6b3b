#!/usr/bin/env bash
# Leave-one-pair-out cross-validation on AdelaideRMF (homography: 17 pairs; fundamental: 19),
# outliers as one more group. Results: runs/cv/adelaide-<type>-<loss>/ (folds/*.json, summary.json).
# Usage: [TAG=name] scripts/cv-adelaide.sh "homography fundamental" "mimi" [jobs] [extra multifit-train flags]
# TAG names a variant run (results in ...-<loss>-<TAG>/), e.g.
#   TAG=graph8 scripts/cv-adelaide.sh "homography fundamental" mimi 2 --neighbors 8 --graph-neighbors 8
set -euo pipefail
cd "$(dirname "$0")/.."
types=${1:-"homography fundamental"}
losses=${2:-mimi}
jobs=${3:-2}
shift $(( $# > 3 ? 3 : $# )) || true
data=${MULTIFIT_DATA:-../shared/datasets}/adelaidermf
cargo build --release --bin multifit-train
for type in $types; do
  e=6; [ "$type" = homography ] && e=8
  for loss in $losses; do
    ./target/release/multifit-train cv --data "$data" --model-type "$type" --loss "$loss" \
      --embed-dim "$e" --width 128 --depth 12 --lr 1e-3 --schedule cosine --epochs 100 --k-max 8 \
      --jobs "$jobs" --out "runs/cv/adelaide-$type-$loss${TAG:+-$TAG}" "$@"
  done
done
