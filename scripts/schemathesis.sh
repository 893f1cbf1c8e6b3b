#!/usr/bin/env bash
# Property-based API tests: Schemathesis generates requests from openapi.yaml (valid ones and,
# with every check on, invalid ones) and checks each answer against the spec.
#
#   scripts/schemathesis.sh --install
#   scripts/schemathesis.sh [--max-examples N] [--time-limit S] [--seed N] [--server PATH]
#                           [-- EXTRA_ST_RUN_ARGS...]
#
# --install creates the venv $SCHEMATHESIS_VENV (default ~/.cache/multifit/schemathesis-VERSION)
# and installs Schemathesis (version pinned below) into it from PyPI, unless that version is
# already there; .ci/run calls it before the tests. A run never installs anything.
#
# A run: 50 examples per operation, the whole run stopped after 600 s, seed 0 (reproducible;
# pass another to explore), target/release/multifit-server (build it first). It starts its own
# server on an ephemeral 127.0.0.1 port and stops it at the end. Schemathesis comes from $ST when
# set, else from the venv. Reports (JUnit XML, NDJSON events) go to target/schemathesis/.
#
# Exit status: Schemathesis's own (0 when every check passed), 124 when the time limit cut the
# run, 2 on a set-up problem. Without python3 or without Schemathesis a run prints a line
# starting SKIP and exits 0 (tests/conformance.rs reports it, and fails under CI).
set -euo pipefail

root=$(cd "$(dirname "$0")/.." && pwd)
version=4.32.5
max_examples=50
time_limit=600
seed=0
server=$root/target/release/multifit-server
venv=${SCHEMATHESIS_VENV:-${XDG_CACHE_HOME:-$HOME/.cache}/multifit/schemathesis-$version}
install=false
out=$root/target/schemathesis
extra=()
while [ $# -gt 0 ]; do
  case $1 in
    --max-examples) max_examples=$2; shift 2 ;;
    --time-limit) time_limit=$2; shift 2 ;;
    --seed) seed=$2; shift 2 ;;
    --server) server=$2; shift 2 ;;
    --install) install=true; shift ;;
    --) shift; extra=("$@"); break ;;
    -h|--help) sed -n '2,/^set -euo/{/^set -euo/d;s/^# \{0,1\}//;p}' "$0"; exit 0 ;;
    *) echo "unknown argument $1 (see --help)" >&2; exit 2 ;;
  esac
done

st=${ST:-$venv/bin/st}
installed() { "$st" --version 2>/dev/null | grep -q "$version"; }
if $install; then
  if [ -n "${ST:-}" ] || installed; then
    echo "# schemathesis $version already installed ($st)"
    exit 0
  fi
  command -v python3 >/dev/null || { echo "--install needs python3" >&2; exit 2; }
  echo "# installing schemathesis $version into $venv"
  if ! { [ -x "$venv/bin/pip" ] || python3 -m venv "$venv"; } \
    || ! "$venv/bin/pip" install --quiet --disable-pip-version-check "schemathesis==$version"; then
    echo "cannot install schemathesis $version from PyPI (offline?); set ST to an installed st" >&2
    exit 2
  fi
  exit 0
fi

if ! command -v python3 >/dev/null; then
  echo "SKIP - schemathesis.sh needs python3 (not found); nothing tested"
  exit 0
fi
if [ -z "${ST:-}" ] && ! installed; then
  echo "SKIP - schemathesis $version is not installed in $venv (scripts/schemathesis.sh --install); nothing tested"
  exit 0
fi
command -v curl >/dev/null || { echo "schemathesis.sh needs curl" >&2; exit 2; }
[ -x "$server" ] || { echo "no server binary at $server (cargo build --release)" >&2; exit 2; }
echo "# $("$st" --version)"

mkdir -p "$out"
# shellcheck source=scripts/lib/server.sh
source "$root/scripts/lib/server.sh"
cleanup() { if [ -n "$server_pid" ]; then kill "$server_pid" 2>/dev/null || true; fi; }
trap cleanup EXIT
start_server "$out" "$server" --addr 127.0.0.1:0 --models "$root/models"
echo "# server pid $server_pid at $base"

start=$(date +%s)
set +e
(cd "$out" && timeout --signal=INT --kill-after=30 "$time_limit" "$st" --config-file "$root/scripts/schemathesis.toml" run "$root/openapi.yaml" \
  --url "$base" \
  --checks all \
  --max-examples "$max_examples" \
  --seed "$seed" \
  --request-timeout 60 \
  --generation-database none \
  --no-color \
  --report junit,ndjson --report-dir "$out" \
  "${extra[@]}")
status=$?
set -e
echo "# schemathesis exit status $status after $(($(date +%s) - start)) s; reports in $out"

stop_server
exit "$status"
