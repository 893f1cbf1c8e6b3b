#!/usr/bin/env bash
# Evaluates the kept fold models of a KT3DMoSeg cross-validation run (runs/cv/<run>/models/) on
# their held-out test clips with the given test-time symmetries, and prints the totals.
# Usage: scripts/cv-test-symmetries.sh runs/cv/<run> "mirror,reverse"   ('' for none)
set -euo pipefail
cd "$(dirname "$0")/.."
dir=$1; sym=${2:-}
data=${MULTIFIT_DATA:-../shared/datasets}/kt3dmoseg_first5
T=./target/release/multifit-train
for m in "$dir"/models/*/; do
  name=$(basename "$m")
  # shellcheck disable=SC2086  # an empty $sym means the flag alone: no symmetries
  $T eval --model "$m" --data "$data/$name.json" --k-max 8 --json --test-symmetry $sym
done | python3 -c '
import json, statistics as st, sys
text, rows, dec = sys.stdin.read(), [], json.JSONDecoder()
i = 0
while text[i:].strip():
    i += len(text[i:]) - len(text[i:].lstrip())
    obj, i = dec.raw_decode(text, i)
    rows += obj["rows"]
for key in ["known", "sod", "silhouette"]:
    e = [100 * r[key]["error"] for r in rows]
    right = 100 * sum(r[key]["k"] == r["k_true"] for r in rows) / len(rows)
    print(f"{key:10s} mean {st.mean(e):.2f} median {st.median(e):.2f} K right {right:.1f} % ({len(rows)} folds)")
'
