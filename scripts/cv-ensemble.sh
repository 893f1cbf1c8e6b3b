#!/usr/bin/env bash
# Ensembles of kept fold models: for every fold of the first run, combines the fold's model of
# each run (multifit-train ensemble) into <out>/models/<fold>/, then evaluates them on the held-out
# test clips (scripts/cv-eval-kept.sh; rows in <out>/kept-eval.json).
# Usage: scripts/cv-ensemble.sh runs/cv/<out> runs/cv/<run1> runs/cv/<run2> [...]
set -euo pipefail
cd "$(dirname "$0")/.."
out=$1; shift
T=${MULTIFIT_TRAIN:-./target/release/multifit-train}
for m in "$1"/models/*/; do
  fold=$(basename "$m")
  models=()
  for run in "$@"; do models+=(--model "$run/models/$fold"); done
  $T ensemble "${models[@]}" --out "$out/models/$fold" --name ensemble >/dev/null
done
echo "$0 $out $*" > "$out/command"
scripts/cv-eval-kept.sh "$out"
