#!/usr/bin/env bash
# Leave-one-sequence-out cross-validation on KT3DMoSeg (22 folds, test = frames 1..5 of the
# held-out sequence), for the losses and protocols given. Results: runs/cv/kt3dmoseg-<protocol>-<loss>/
# (folds/*.json, summary.json). Finished folds are kept; rerunning resumes.
# Usage: [JOBS=2] [EPOCHS=n] [TAG=name] scripts/cv-kt3dmoseg.sh "vanilla augment" "mimi ce l2" [extra flags]
# EPOCHS overrides the protocol's epochs; TAG names a variant run (results in ...-<loss>-<TAG>/), e.g.
#   EPOCHS=6 TAG=sliding-sym scripts/cv-kt3dmoseg.sh augment ce --clip-stride 1 --symmetry mirror,reverse
set -euo pipefail
cd "$(dirname "$0")/.."
protocols=${1:-vanilla}
losses=${2:-"mimi ce l2"}
shift $(( $# > 2 ? 2 : $# )) || true
data=${MULTIFIT_DATA:-../shared/datasets}/kt3dmoseg
cargo build --release --bin multifit-train
for protocol in $protocols; do
  for loss in $losses; do
    epochs=150
    [ "$protocol" != vanilla ] && epochs=60
    epochs=${EPOCHS:-$epochs}
    ./target/release/multifit-train cv --data "$data" --protocol "$protocol" --loss "$loss" \
      --embed-dim 5 --width 128 --depth 12 --lr 1e-3 --schedule cosine --epochs "$epochs" --k-max 8 \
      --jobs "${JOBS:-2}" --out "runs/cv/kt3dmoseg-$protocol-$loss${TAG:+-$TAG}" "$@"
  done
done
