#!/usr/bin/env bash
# Smoke test of a running multifit-server with curl, as a user would.
# Usage: scripts/smoke.sh [BASE_URL]   (default http://127.0.0.1:8080)
# Needs bash, curl and python3 (JSON checks). Data: $MULTIFIT_DATA or ../shared/datasets.
set -euo pipefail
base=${1:-http://127.0.0.1:8080}
data=${MULTIFIT_DATA:-$(dirname "$0")/../../shared/datasets}
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
passed=0
failed=0

ok() { echo "ok - $1"; passed=$((passed + 1)); }
fail() { echo "FAIL - $1: $2"; failed=$((failed + 1)); }

# request METHOD PATH [BODY_FILE] [CONTENT_TYPE] -> sets $status, body in $tmp/out
request() {
  local args=(-s -o "$tmp/out" -w '%{http_code}' -X "$1" "$base$2")
  if [ -n "${3:-}" ]; then args+=(--data-binary "@$3" -H "content-type: ${4:-application/json}"); fi
  status=$(curl "${args[@]}") || status=000
}

# check WHAT EXPECTED_STATUS PYTHON_ASSERTION (on `v`, the parsed body; empty = status only)
check() {
  local what=$1 want=$2 assertion=${3:-}
  if [ "$status" != "$want" ]; then fail "$what" "status $status, expected $want: $(head -c 300 "$tmp/out")"; return; fi
  if [ -n "$assertion" ] && ! python3 -c "import json,sys; v=json.load(open('$tmp/out')); assert $assertion" 2>"$tmp/err"; then
    fail "$what" "$(tail -1 "$tmp/err"): $(head -c 300 "$tmp/out")"; return
  fi
  ok "$what"
}

# body FILE PYTHON_EXPRESSION: writes json.dumps(EXPRESSION) to FILE; `d(path)` loads a dataset file.
body() {
  python3 -c "import json,sys; d=lambda p: json.load(open('$data/'+p)); json.dump($2, open('$1','w'))"
}

error_is() { echo "v['error']['code'] == '$1' and isinstance(v['error']['message'], str)"; }

request GET /health/live; check "live" 200 "v['status'] == 'live'"
request GET /health/ready; check "ready" 200 "v['status'] == 'ready'"
request GET /v1/models
check "models listed" 200 "{'adelaide-fundamental','adelaide-homography','kt3dmoseg','lce'} <= {m['name'] for m in v['models']}"
request GET /v1/models/kt3dmoseg; check "model card" 200 "v['kind'] == 'trajectories' and v['input_dim'] == 10"
request GET /v1/models/nope; check "unknown model card is 404" 404 "$(error_is not_found)"

seq=kt3dmoseg_first5/Seq009_Clip01.json
body "$tmp/kt.json" "{'kind': d('$seq')['kind'], 'points': d('$seq')['points'], 'image_size': d('$seq')['image_size']}"
request POST /v1/fit "$tmp/kt.json"
check "fit KT3DMoSeg Seq009_Clip01" 200 "len(v['labels']) == len(json.load(open('$data/$seq'))['points']) and 1 <= v['k'] <= 8 and all(b['r'] <= a['r'] * (1 + 1e-9) + 1e-9 for a, b in zip(v['residuals'], v['residuals'][1:]))"
body "$tmp/kt-k.json" "{'kind': 'trajectories', 'points': d('$seq')['points'], 'image_size': d('$seq')['image_size'], 'k': d('$seq')['num_models'], 'seed': 1}"
request POST /v1/fit "$tmp/kt-k.json"; cp "$tmp/out" "$tmp/first"
request POST /v1/fit "$tmp/kt-k.json"
check "same input and seed, same labels" 200 "v['labels'] == json.load(open('$tmp/first'))['labels']"
body "$tmp/ad.json" "{'kind': 'correspondences', 'points': d('adelaidermf/bonython.json')['points'], 'image_size': d('adelaidermf/bonython.json')['image_size'], 'model': 'adelaide-homography'}"
request POST /v1/fit "$tmp/ad.json"; check "fit AdelaideRMF bonython" 200 "v['model']['name'] == 'adelaide-homography'"
body "$tmp/p2.json" "{'kind': 'points2d', 'points': [[0,0],[1,0.02],[2,0],[3,0.01],[0,5],[0.5,5.9],[1,6],[1.5,5.9],[2,5]]}"
request POST /v1/fit "$tmp/p2.json"; check "fit points2d with the lce model" 200 "v['model']['name'] == 'lce' and len(v['labels']) == 9"
body "$tmp/batch.json" "{'requests': [json.load(open('$tmp/p2.json')), {'kind': 'points2d', 'points': []}, json.load(open('$tmp/p2.json'))]}"
request POST /v1/fit/batch "$tmp/batch.json"
check "batch keeps order, one error entry" 200 "len(v['results']) == 3 and v['results'][1]['error']['code'] == 'invalid_points' and v['results'][2]['labels'] == v['results'][0]['labels']"

printf '{"kind": "points2d", "points": [[0' > "$tmp/trunc.json"
request POST /v1/fit "$tmp/trunc.json"; check "truncated JSON" 400 "$(error_is malformed_json)"
request POST /v1/fit "$tmp/p2.json" text/plain; check "wrong content type" 415 "$(error_is unsupported_media_type)"
body "$tmp/e1.json" "{'kind': 'points2d', 'points': []}"
request POST /v1/fit "$tmp/e1.json"; check "no points" 422 "$(error_is invalid_points)"
body "$tmp/e2.json" "{'kind': 'points2d', 'points': [[0,0],[1,1]], 'k': 3}"
request POST /v1/fit "$tmp/e2.json"; check "k > N" 422 "$(error_is invalid_k)"
body "$tmp/e3.json" "{'kind': 'points2d', 'points': [[0,0],[1,1]], 'model': 'nope'}"
request POST /v1/fit "$tmp/e3.json"; check "unknown model" 422 "$(error_is unknown_model)"
body "$tmp/e4.json" "{'kind': 'voxels', 'points': [[0,0],[1,1]]}"
request POST /v1/fit "$tmp/e4.json"; check "unknown kind" 422 "$(error_is unknown_kind)"
body "$tmp/e5.json" "{'kind': 'points2d', 'points': [[0,0],[1,1]], 'colour': 'red'}"
request POST /v1/fit "$tmp/e5.json"; check "unknown field" 422 "$(error_is invalid_request)"

request GET /metrics
if [ "$status" = 200 ] && grep -q '^multifit_requests_total' "$tmp/out"; then ok "metrics"; else fail "metrics" "status $status"; fi
request GET /openapi.yaml
if [ "$status" = 200 ] && head -1 "$tmp/out" | grep -q '^openapi: 3'; then ok "openapi.yaml"; else fail "openapi.yaml" "status $status"; fi

echo "$passed passed, $failed failed"
[ "$failed" -eq 0 ]
