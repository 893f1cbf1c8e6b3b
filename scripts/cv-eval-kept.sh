#!/usr/bin/env bash
# Evaluates the kept fold models of a cross-validation run (<run>/models/<fold>/) on their
# held-out sequences, with the given test-time symmetries (default: none), prints the totals and
# writes them with every fold's row to <run>/kept-eval[-<symmetries>][-<TAG>].json (the totals in
# the shape of a cv run's summary.json).
# Usage: [DATA=dir] [TAG=name] scripts/cv-eval-kept.sh runs/cv/<run> ["mirror,reverse"] [eval flags]
#   DATA: the held-out sequences, <DATA>/<fold>.json (default: KT3DMoSeg frames 1..5; AdelaideRMF:
#   DATA=../shared/datasets/adelaidermf). Further flags go to `multifit-train eval`, e.g.
#   TAG=refine scripts/cv-eval-kept.sh runs/cv/<run> "" --refine on
#   TAG=all-frames DATA=../shared/datasets/kt3dmoseg scripts/cv-eval-kept.sh runs/cv/<run> "" --frames all
set -euo pipefail
cd "$(dirname "$0")/.."
dir=$1; sym=${2:-}
shift $(( $# > 2 ? 2 : $# )) || true
data=${DATA:-${MULTIFIT_DATA:-../shared/datasets}/kt3dmoseg_first5}
T=${MULTIFIT_TRAIN:-./target/release/multifit-train}
for m in "$dir"/models/*/; do
  name=$(basename "$m")
  # shellcheck disable=SC2086  # an empty $sym means the flag alone: no symmetries
  $T eval --model "$m" --data "$data/$name.json" --k-max 8 --json --test-symmetry $sym "$@"
done | python3 -c '
import json, statistics as st, sys
text, rows, dec = sys.stdin.read(), [], json.JSONDecoder()
i = 0
while text[i:].strip():
    i += len(text[i:]) - len(text[i:].lstrip())
    obj, i = dec.raw_decode(text, i)
    rows += obj["rows"]
totals = {"samples": len(rows)}
for key in ["known", "sod", "silhouette"]:
    e = [r[key]["error"] for r in rows]
    right = sum(r[key]["k"] == r["k_true"] for r in rows) / len(rows)
    nmi = st.mean(r[key]["nmi"] for r in rows)
    totals[key] = {"mean_error": st.mean(e), "median_error": st.median(e), "mean_nmi": nmi, "k_correct": right}
    print(f"{key:10s} mean {100 * st.mean(e):.2f} median {100 * st.median(e):.2f} K right {100 * right:.1f} % ({len(rows)} folds)")
json.dump({"totals": totals, "rows": rows}, open(sys.argv[1], "w"), indent=1)
' "$dir/kept-eval${sym:+-${sym//,/-}}${TAG:+-$TAG}.json"
