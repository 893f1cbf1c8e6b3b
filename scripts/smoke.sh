#!/usr/bin/env bash
# Smoke test of a RUNNING multifit-server, with curl, as a user would call it.
#
#   scripts/smoke.sh [BASE_URL]          (default http://127.0.0.1:8080)
#
# Needs bash, curl and python3 (standard library only, for the JSON checks). The benchmark files
# come from $MULTIFIT_DATA (default: ../shared/datasets next to the project). Prints one
# `ok - ...` or `FAIL - ...: ...` line per check, then `N passed, M failed`; exits 1 on a failure.
set -euo pipefail

base=${1:-http://127.0.0.1:8080}
data=${MULTIFIT_DATA:-"$(dirname "$0")/../../shared/datasets"}
kt=kt3dmoseg_first5/Seq009_Clip01.json
ad=adelaidermf/bonython.json

for tool in curl python3; do
  command -v "$tool" >/dev/null || { echo "smoke.sh needs $tool" >&2; exit 2; }
done
for file in "$kt" "$ad"; do
  [ -f "$data/$file" ] || { echo "missing $data/$file (set MULTIFIT_DATA)" >&2; exit 2; }
done

tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
passed=0
failed=0

ok() { echo "ok - $1"; passed=$((passed + 1)); }
fail() { echo "FAIL - $1: $2"; failed=$((failed + 1)); }

# The JSON checks, one python function each: `check.py CHECK ANSWER_FILE [ARGS...]` prints nothing
# when the answer passes CHECK, else one line saying what is wrong.
cat > "$tmp/check.py" <<'PY'
import json
import sys


def status(v, want):
    """A health answer {"status": want}."""
    if v["status"] != want:
        return f"status field {v['status']!r}, expected {want!r}"


def models(v, *names):
    """GET /v1/models lists every one of names."""
    listed = [m["name"] for m in v["models"]]
    missing = [n for n in names if n not in listed]
    if missing:
        return f"missing {missing}; listed {listed}"


def card(v, name, kind):
    """A model card of the given name and kind."""
    if (v["name"], v["kind"]) != (name, kind):
        return f"name {v['name']!r}, kind {v['kind']!r}; expected {name!r}, {kind!r}"


def error(v, code):
    """An error answer {"error": {"code": code, "message": "..."}}."""
    e = v["error"]
    if e["code"] != code:
        return f"error.code {e['code']!r}, expected {code!r}"
    if not isinstance(e["message"], str) or not e["message"]:
        return "error.message missing or empty"


def fit(v, n):
    """A fit of n points: n labels in 0..k-1, 1 <= k <= 8, residuals r(K) non-increasing."""
    n, k, labels = int(n), v["k"], v["labels"]
    if len(labels) != n:
        return f"{len(labels)} labels for {n} points"
    if not 1 <= k <= 8:
        return f"k = {k}, expected 1..8"
    if not all(0 <= label < k for label in labels):
        return f"a label outside 0..{k - 1}"
    r = [x["r"] for x in v["residuals"]]
    if not r:
        return "no residuals"
    if any(b > a * (1 + 1e-9) + 1e-9 for a, b in zip(r, r[1:])):
        return f"residuals increase: {r}"


def fitted_by(v, model, n):
    """A fit of n points by the named model."""
    if v["model"]["name"] != model:
        return f"model {v['model']['name']!r}, expected {model!r}"
    if len(v["labels"]) != int(n):
        return f"{len(v['labels'])} labels for {n} points"


def same_labels(v, other_file):
    """The same labels as the answer saved in other_file."""
    if v["labels"] != json.load(open(other_file))["labels"]:
        return "labels differ between the two answers"


def batch(v):
    """Three results in order: a fit, an invalid_points error, a fit."""
    results = v["results"]
    if len(results) != 3:
        return f"{len(results)} results for 3 requests"
    if "labels" not in results[0] or "labels" not in results[2]:
        return "a good entry has no labels"
    code = results[1]["error"]["code"]
    if code != "invalid_points":
        return f"results[1].error.code {code!r}, expected 'invalid_points'"


check, answer, args = globals()[sys.argv[1]], sys.argv[2], sys.argv[3:]
try:
    v = json.load(open(answer))
except ValueError as e:
    print(f"answer is not JSON ({e})")
    sys.exit()
try:
    problem = check(v, *args)
except (KeyError, IndexError, TypeError, AttributeError) as e:
    problem = f"unexpected answer shape ({type(e).__name__}: {e})"
if problem:
    print(problem)
PY

# HTTP: `get PATH` or `post PATH BODY_FILE [CONTENT_TYPE]`. The answer's body goes to
# $tmp/answer and its status code to $status (000 when the server could not be reached).
call() {
  : > "$tmp/answer"
  status=$(curl --silent --max-time 60 --output "$tmp/answer" --write-out '%{http_code}' "$@") \
    || status=000
}
get() { call "$base$1"; }
post() { call "$base$1" --header "content-type: ${3:-application/json}" --data-binary "@$2"; }

# The first 200 characters of the last answer, on one line (for FAIL details).
answer_start() { head -c 200 "$tmp/answer" | tr '\n' ' '; }

# expect WHAT STATUS [CHECK ARGS...]: the last answer has STATUS and passes CHECK of check.py.
expect() {
  local what=$1 want=$2 problem
  shift 2
  if [ "$status" != "$want" ]; then
    fail "$what" "status $status, expected $want; body: $(answer_start)"
    return
  fi
  if [ $# -gt 0 ]; then
    problem=$(python3 "$tmp/check.py" "$1" "$tmp/answer" "${@:2}") || problem="check $1 crashed"
    if [ -n "$problem" ]; then
      fail "$what" "$problem"
      return
    fi
  fi
  ok "$what"
}

# check_get WHAT PATH STATUS [CHECK ARGS...]
check_get() {
  local what=$1 path=$2
  shift 2
  get "$path"
  expect "$what" "$@"
}

# check_error WHAT STATUS CODE BODY [CONTENT_TYPE]: POST /v1/fit of the literal BODY answers
# STATUS with {"error": {"code": CODE, "message": ...}}.
check_error() {
  printf '%s' "$4" > "$tmp/bad.json"
  post /v1/fit "$tmp/bad.json" "${5:-application/json}"
  expect "$1" "$2" error "$3"
}

# check_contains WHAT PATH TEXT: GET PATH is 200 and its body contains TEXT.
check_contains() {
  get "$2"
  if [ "$status" != 200 ]; then
    fail "$1" "status $status, expected 200"
  elif grep -qF -- "$3" "$tmp/answer"; then
    ok "$1"
  else
    fail "$1" "no '$3' in the body"
  fi
}

# check_starts_with WHAT PATH TEXT: GET PATH is 200 and its body starts with TEXT.
check_starts_with() {
  get "$2"
  if [ "$status" != 200 ]; then
    fail "$1" "status $status, expected 200"
  elif [ "$(head -c "${#3}" "$tmp/answer")" = "$3" ]; then
    ok "$1"
  else
    fail "$1" "body starts with: $(answer_start)"
  fi
}

# fit_body DATASET OUT [EXTRA_JSON]: writes {"kind", "points", "image_size"} of a dataset file
# (a path under $data), plus the fields of EXTRA_JSON, to OUT.
fit_body() {
  python3 - "$data/$1" "$2" "${3:-"{}"}" <<'PY'
import json, sys
dataset, out, extra = json.load(open(sys.argv[1])), sys.argv[2], json.loads(sys.argv[3])
body = {"kind": dataset["kind"], "points": dataset["points"], "image_size": dataset["image_size"]}
body.update(extra)
json.dump(body, open(out, "w"))
PY
}

# dataset_field DATASET FIELD: prints a number field of a dataset file; FIELD `points` prints the count.
dataset_field() {
  python3 - "$data/$1" "$2" <<'PY'
import json, sys
value = json.load(open(sys.argv[1]))[sys.argv[2]]
print(len(value) if isinstance(value, list) else value)
PY
}

echo "# multifit smoke test against $base"

check_get "GET /health/live is 200" /health/live 200 status live
check_get "GET /health/ready is 200" /health/ready 200 status ready
check_get "GET /v1/models lists the shipped models" /v1/models 200 \
  models adelaide-fundamental adelaide-homography kt3dmoseg lce motion
check_get "GET /v1/models/kt3dmoseg is a trajectories card" /v1/models/kt3dmoseg 200 \
  card kt3dmoseg trajectories
check_get "GET /v1/models/nope is 404 not_found" /v1/models/nope 404 error not_found

n=$(dataset_field "$kt" points)
fit_body "$kt" "$tmp/kt.json"
post /v1/fit "$tmp/kt.json"
expect "fit $kt: $n labels, k in 1..8, residuals non-increasing" 200 fit "$n"

k=$(dataset_field "$kt" num_models)
fit_body "$kt" "$tmp/kt-known-k.json" "{\"k\": $k, \"seed\": 1}"
post /v1/fit "$tmp/kt-known-k.json"
expect "fit $kt with k = $k and seed 1" 200 fit "$n"
cp "$tmp/answer" "$tmp/first-answer.json"
post /v1/fit "$tmp/kt-known-k.json"
expect "same input and seed give the same labels" 200 same_labels "$tmp/first-answer.json"

fit_body "$ad" "$tmp/ad.json" '{"model": "adelaide-homography"}'
post /v1/fit "$tmp/ad.json"
expect "fit $ad with adelaide-homography" 200 \
  fitted_by adelaide-homography "$(dataset_field "$ad" points)"

points2d='{"kind": "points2d", "points": [[0, 0], [1, 0.02], [2, 0], [3, 0.01], [0, 5], [0.5, 5.9], [1, 6], [1.5, 5.9], [2, 5]]}'
printf '%s' "$points2d" > "$tmp/points2d.json"
post /v1/fit "$tmp/points2d.json"
expect "fit points2d with the default model lce" 200 fitted_by lce 9

printf '%s' "{\"requests\": [$points2d, {\"kind\": \"points2d\", \"points\": []}, $points2d]}" \
  > "$tmp/batch.json"
post /v1/fit/batch "$tmp/batch.json"
expect "batch of 2 good and 1 bad entry answers each in order" 200 batch

check_error "truncated JSON is 400 malformed_json" 400 malformed_json \
  '{"kind": "points2d", "points": [[0'
check_error "text/plain is 415 unsupported_media_type" 415 unsupported_media_type \
  "$points2d" text/plain
check_error "no points is 422 invalid_points" 422 invalid_points \
  '{"kind": "points2d", "points": []}'
check_error "k larger than N is 422 invalid_k" 422 invalid_k \
  '{"kind": "points2d", "points": [[0, 0], [1, 1]], "k": 3}'
check_error "unknown model is 422 unknown_model" 422 unknown_model \
  '{"kind": "points2d", "points": [[0, 0], [1, 1]], "model": "nope"}'
check_error "unknown kind is 422 unknown_kind" 422 unknown_kind \
  '{"kind": "voxels", "points": [[0, 0], [1, 1]]}'
check_error "unknown field is 422 invalid_request" 422 invalid_request \
  '{"kind": "points2d", "points": [[0, 0], [1, 1]], "colour": "red"}'

check_contains "GET /metrics has multifit_requests_total" /metrics multifit_requests_total
check_starts_with "GET /openapi.yaml is an OpenAPI 3 document" /openapi.yaml "openapi: 3"

echo "$passed passed, $failed failed"
if [ "$failed" -gt 0 ]; then
  exit 1
fi
