#!/usr/bin/env bash
# Evaluates the kept fold models of a KT3DMoSeg cross-validation run (<run>/models/<fold>/) on
# their held-out test clips, with the given test-time symmetries (default: none), prints the
# totals and writes every fold's row to <run>/kept-eval[-<symmetries>].json.
# Usage: scripts/cv-eval-kept.sh runs/cv/<run> ["mirror,reverse"]
set -euo pipefail
cd "$(dirname "$0")/.."
dir=$1; sym=${2:-}
data=${MULTIFIT_DATA:-../shared/datasets}/kt3dmoseg_first5
T=${MULTIFIT_TRAIN:-./target/release/multifit-train}
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
totals = {}
for key in ["known", "sod", "silhouette"]:
    e = [100 * r[key]["error"] for r in rows]
    right = 100 * sum(r[key]["k"] == r["k_true"] for r in rows) / len(rows)
    totals[key] = {"mean_error": st.mean(e), "median_error": st.median(e), "k_correct": right}
    print(f"{key:10s} mean {st.mean(e):.2f} median {st.median(e):.2f} K right {right:.1f} % ({len(rows)} folds)")
json.dump({"totals": totals, "rows": rows}, open(sys.argv[1], "w"), indent=1)
' "$dir/kept-eval${sym:+-${sym//,/-}}.json"
