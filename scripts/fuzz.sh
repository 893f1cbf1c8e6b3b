#!/usr/bin/env bash
# Fuzzes request parsing and validation (fuzz/fuzz_targets/fit_request.rs) for a bounded time.
#
#   scripts/fuzz.sh [SECONDS]            (default 300)
#
# Installs cargo-fuzz if missing, builds the target with the stable toolchain (RUSTC_BOOTSTRAP=1
# lets it take cargo-fuzz's nightly flags), then runs libFuzzer for SECONDS over the seeds in
# fuzz/seeds/fit_request (the corpus it grows goes to fuzz/corpus/fit_request, crashes to
# fuzz/artifacts/fit_request). Prints the build time, executions, exec/s, coverage and whether a
# crash was found; exits 1 on a crash (or a libFuzzer timeout / out-of-memory), 2 on a setup error.
#
# Environment: FUZZ_SANITIZER (address; `none` is faster and needs no sanitizer runtime),
# FUZZ_NICE (5), FUZZ_TIMEOUT (seconds one input may take before it counts as a crash, 30),
# FUZZ_MAX_LEN (largest input in bytes, 4096).
# The first build compiles burn with coverage instrumentation: several minutes on 2 cores.
set -euo pipefail

seconds=${1:-300}
case $seconds in '' | *[!0-9]*) echo "usage: scripts/fuzz.sh [SECONDS]" >&2; exit 2 ;; esac
sanitizer=${FUZZ_SANITIZER:-address}
nice_level=${FUZZ_NICE:-5}
timeout=${FUZZ_TIMEOUT:-30}
max_len=${FUZZ_MAX_LEN:-4096}
target=fit_request

root=$(cd "$(dirname "$0")/.." && pwd)
cd "$root"
export RUSTC_BOOTSTRAP=1

if ! cargo fuzz --version >/dev/null 2>&1; then
  echo "installing cargo-fuzz (a few minutes)" >&2
  nice -n "$nice_level" cargo install cargo-fuzz --locked
fi

# The same flags for build and run, so that `run` does not rebuild.
flags=(--release --debug-assertions --sanitizer "$sanitizer")

start=$(date +%s)
nice -n "$nice_level" cargo fuzz build "${flags[@]}" "$target"
build_s=$(($(date +%s) - start))

corpus=$root/fuzz/corpus/$target
seeds=$root/fuzz/seeds/$target
artifacts=$root/fuzz/artifacts/$target
mkdir -p "$corpus" "$artifacts"
log=$artifacts/run-$(date +%Y%m%d-%H%M%S).log

set +e
nice -n "$nice_level" cargo fuzz run "${flags[@]}" "$target" "$corpus" "$seeds" -- \
  -max_total_time="$seconds" -timeout="$timeout" -max_len="$max_len" \
  -dict="$root/fuzz/$target.dict" -print_final_stats=1 \
  2>&1 | tee "$log"
status=${PIPESTATUS[0]}
set -e

# (grep finds nothing on a clean run: `|| true` keeps pipefail from ending the script)
stat() { { grep -Eo "^stat::$1: *[0-9]+" "$log" | tail -1 | grep -Eo '[0-9]+$'; } || echo "?"; }
last=$({ grep -E '^#[0-9]+' "$log" | tail -1; } || true)
crash=$({ grep -Eo "Test unit written to [^ ]+" "$log" | tail -1 | sed 's/Test unit written to //'; } || true)

echo
echo "== fuzz summary: $target, sanitizer $sanitizer, $seconds s =="
echo "build:        ${build_s} s"
echo "executions:   $(stat number_of_executed_units)"
echo "exec/s:       $(stat average_exec_per_sec)"
echo "coverage:     $(grep -Eo 'cov: [0-9]+ ft: [0-9]+' <<<"$last" || echo '?') (edges, features), corpus $(grep -Eo 'corp: [^ ]+' <<<"$last" || echo '?')"
echo "new units:    $(stat new_units_added)"
echo "peak RSS:     $(stat peak_rss_mb) MB"
echo "log:          $log"
if [ "$status" -ne 0 ] || [ -n "$crash" ]; then
  echo "crash:        YES (exit $status) ${crash:-}"
  grep -E "panicked at|^thread '|ERROR: libFuzzer|SUMMARY:" "$log" | head -5 || true
  if [ -n "$crash" ]; then
    echo "reproduce:    RUSTC_BOOTSTRAP=1 cargo fuzz run ${flags[*]} $target $crash"
    echo "minimise:     RUSTC_BOOTSTRAP=1 cargo fuzz tmin ${flags[*]} $target $crash"
  fi
  exit 1
fi
echo "crash:        none"
