#!/usr/bin/env bash
# Load test of multifit-server on loopback with wrk: sustained concurrency far above the worker
# count against a small queue, so the server must shed load (429) without errors, lost requests
# or growing memory.
#
#   scripts/loadtest.sh [--duration S] [--connections C] [--points N[,N...]] [--queue-capacity Q]
#                       [--workers W] [--port P] [--wrk-timeout S] [--server PATH] [--out DIR]
#
# Defaults: 60 s per phase, 64 connections, phases of N = 1000 and N = 20000 correspondences,
# queue capacity 8, the server's default worker count, an ephemeral port on 127.0.0.1.
# Each phase starts its own server (target/release/multifit-server; build it first), so the
# peak RSS (VmHWM) of a phase is that phase's alone. The body is a /v1/fit request for model
# adelaide-homography built by scripts/loadtest-body.py from AdelaideRMF unihouse (2084
# correspondences, 980 x 735 pixels) in $MULTIFIT_DATA (default ../shared/datasets): a seeded
# random subset when N <= 2084, else every row plus copies jittered by up to 0.5 pixel.
# wrk runs one thread per connection so that scripts/loadtest.lua can time every request and
# give latencies per status. Results and logs: target/loadtest/n<N>/ (summary.json, wrk.txt,
# rss.tsv, metrics-*.prom, server.log).
#
# Per phase it prints throughput, latency (wrk's, over every answer, and per status), counts by
# status, the share of 429, the RSS sampled every second from /proc/PID/status (peak, VmHWM, first
# vs last 10 s), wrk's socket errors and timeouts, and the /metrics counters for the same window.
# Exits 1 on any 5xx, any request lost without an answer (wrk connect/read/write errors or
# timeouts), a crashed server or a failed warm-up request; 2 on a usage or set-up problem.
# Needs wrk (apt-get install wrk), curl and python3 (standard library only).
set -euo pipefail

root=$(cd "$(dirname "$0")/.." && pwd)
duration=60
connections=64
points=1000,20000
queue=8
workers=
port=0
wrk_timeout=60
server=$root/target/release/multifit-server
out=$root/target/loadtest
data=${MULTIFIT_DATA:-"$root/../shared/datasets"}
dataset=adelaidermf/unihouse.json

usage() { sed -n '2,/^set -euo/{/^set -euo/d;s/^# \{0,1\}//;p}' "$0"; }
while [ $# -gt 0 ]; do
  case $1 in
    --duration) duration=$2; shift 2 ;;
    --connections) connections=$2; shift 2 ;;
    --points) points=$2; shift 2 ;;
    --queue-capacity) queue=$2; shift 2 ;;
    --workers) workers=$2; shift 2 ;;
    --port) port=$2; shift 2 ;;
    --wrk-timeout) wrk_timeout=$2; shift 2 ;;
    --server) server=$2; shift 2 ;;
    --out) out=$2; shift 2 ;;
    -h|--help) usage; exit 0 ;;
    *) echo "unknown argument $1 (see --help)" >&2; exit 2 ;;
  esac
done

for tool in wrk curl python3; do
  command -v "$tool" >/dev/null || { echo "loadtest.sh needs $tool" >&2; exit 2; }
done
[ -x "$server" ] || { echo "no server binary at $server (cargo build --release)" >&2; exit 2; }
[ -f "$data/$dataset" ] || { echo "missing $data/$dataset (set MULTIFIT_DATA)" >&2; exit 2; }
mkdir -p "$out"

# shellcheck source=scripts/lib/server.sh
source "$root/scripts/lib/server.sh"
sampler_pid=
cleanup() {
  if [ -n "$sampler_pid" ]; then kill "$sampler_pid" 2>/dev/null || true; fi
  if [ -n "$server_pid" ]; then kill "$server_pid" 2>/dev/null || true; fi
}
trap cleanup EXIT

# make_body N FILE: the /v1/fit body of N correspondences.
make_body() { MULTIFIT_DATA=$data python3 "$root/scripts/loadtest-body.py" "$1" "$2" "$data/$dataset"; }

# run_server LOG_DIR: this run's server; sets $server_pid and $base once it is ready.
run_server() {
  local args=(--addr "127.0.0.1:$port" --models "$root/models" --queue-capacity "$queue")
  [ -n "$workers" ] && args+=(--workers "$workers")
  start_server "$1" "$server" "${args[@]}"
}

# queue_depth: the multifit_queue_depth gauge now.
queue_depth() {
  curl -s "$base/metrics" | sed -n 's/^multifit_queue_depth \([0-9]*\).*/\1/p'
}

status=0
summaries=()
IFS=, read -r -a phases <<< "$points"
for n in "${phases[@]}"; do
  dir=$out/n$n
  rm -rf "$dir"
  mkdir -p "$dir"
  body=$dir/body.json
  make_body "$n" "$body"
  echo "# phase N = $n: body $(wc -c < "$body") bytes, $connections connections, ${duration} s," \
    "queue capacity $queue, workers ${workers:-default}"
  run_server "$dir"
  echo "# server pid $server_pid at $base"

  # One request alone: the body must be accepted, and it gives the unloaded latency.
  warm=$(curl -s -o "$dir/warmup.json" -w '%{http_code} %{time_total}' --max-time 120 \
    -H 'content-type: application/json' --data-binary "@$body" "$base/v1/fit") || warm="000 0"
  echo "# warm-up: status ${warm% *}, ${warm#* } s"
  if [ "${warm% *}" != 200 ]; then
    echo "FAIL - warm-up request answered ${warm% *}: $(head -c 300 "$dir/warmup.json")"
    status=1
    stop_server
    continue
  fi
  curl -s "$base/metrics" > "$dir/metrics-before.prom"

  # RSS every second while wrk runs: milliseconds since start, VmRSS in kB.
  (
    start=$(date +%s%N)
    while kill -0 "$server_pid" 2>/dev/null; do
      rss=$(awk '/^VmRSS:/ {print $2}' "/proc/$server_pid/status" 2>/dev/null) || break
      echo "$((($(date +%s%N) - start) / 1000000)) $rss"
      sleep 1
    done
  ) > "$dir/rss.tsv" &
  sampler_pid=$!

  MULTIFIT_LOADTEST_BODY=$body wrk -t "$connections" -c "$connections" -d "${duration}s" \
    --timeout "${wrk_timeout}s" --latency -s "$root/scripts/loadtest.lua" "$base/v1/fit" \
    > "$dir/wrk.txt" 2>&1 || echo "wrk exited with status $?" >> "$dir/wrk.txt"
  kill "$sampler_pid" 2>/dev/null || true
  wait "$sampler_pid" 2>/dev/null || true
  sampler_pid=

  alive=1
  kill -0 "$server_pid" 2>/dev/null || alive=0
  hwm=0
  if [ "$alive" = 1 ]; then
    # wrk drops its connections at the end: their queued fits are dropped at once, running ones
    # finish unrecorded (see scripts/check-abandoned.sh). Wait for the gauge to settle.
    for _ in $(seq 600); do
      [ "$(queue_depth)" = 0 ] && break
      sleep 0.1
    done
    curl -s "$base/metrics" > "$dir/metrics-after.prom"
    hwm=$(awk '/^VmHWM:/ {print $2}' "/proc/$server_pid/status")
    stop_server
  else
    echo "FAIL - the server died during the run; see $dir/server.log"
    status=1
    : > "$dir/metrics-after.prom"
  fi

  python3 - "$dir" "$n" "$hwm" "$alive" "$connections" <<'PY' || status=1
import json, re, sys
from pathlib import Path

d, n, hwm_kb, alive, connections = Path(sys.argv[1]), int(sys.argv[2]), int(sys.argv[3]), \
    sys.argv[4] == "1", int(sys.argv[5])
wrk_text = (d / "wrk.txt").read_text()
m = re.search(r"^LOADTEST_JSON (.*)$", wrk_text, re.M)
if not m:
    print("FAIL - no LOADTEST_JSON line from wrk:\n" + wrk_text)
    sys.exit(1)
w = json.loads(m.group(1))


def prom(path):
    out = {}
    for line in Path(path).read_text().splitlines():
        if line and not line.startswith("#"):
            name, _, value = line.rpartition(" ")
            out[name] = float(value)
    return out


before, after = prom(d / "metrics-before.prom"), prom(d / "metrics-after.prom")


def delta(name):
    return after.get(name, 0) - before.get(name, 0)


server_status = {}
for key in set(before) | set(after):
    sm = re.match(r'multifit_requests_total\{endpoint="/v1/fit",status="(\d+)"\}', key)
    if sm and delta(key):
        server_status[sm.group(1)] = int(delta(key))

secs = w["duration_us"] / 1e6
statuses = w["statuses"]
count = lambda s: statuses.get(s, {}).get("count", 0)
answered = sum(v["count"] for v in statuses.values())
n5xx = sum(v["count"] for s, v in statuses.items() if s.startswith("5"))
other = {s: v["count"] for s, v in statuses.items() if s not in ("200", "429") and not s.startswith("5")}
e = w["errors"]
lost = e["connect"] + e["read"] + e["write"] + e["timeout"]
server_5xx = sum(v for s, v in server_status.items() if s.startswith("5"))

rss = [(int(t) / 1e3, int(kb)) for t, kb in (l.split() for l in (d / "rss.tsv").read_text().splitlines() if l.strip())]
kbs = [kb for _, kb in rss]
mean = lambda xs: sum(xs) / len(xs) if xs else 0
# Flat: the last 10 s against the first 10 s once the first 5 s (the ramp-up, while the first
# bodies and fits size the allocator's arenas) are past; halves of that when the run is short.
ramp = min(5, len(kbs) // 4)
steady = kbs[ramp:]
win = min(10, len(steady) // 2) or 1
first, last = mean(steady[:win]), mean(steady[-win:])
growth = (last - first) / first if first else 0.0
flat = growth <= 0.10
raw_first, raw_last = mean(kbs[:10]), mean(kbs[-10:])
mib = lambda kb: kb / 1024
ms = lambda us: "n/a" if us is None else f"{us / 1e3:.1f} ms"

print(f"throughput: {answered / secs:.1f} answers/s over {secs:.1f} s "
      f"({count('200') / secs:.2f} fits/s answered 200)")
print(f"latency over every answer (wrk): p50 {ms(w['latency_us']['p50'])}, "
      f"p99 {ms(w['latency_us']['p99'])}, max {ms(w['latency_us']['max'])}")
for s in sorted(statuses):
    v = statuses[s]
    print(f"  status {s}: {v['count']} answers ({100 * v['count'] / max(answered, 1):.1f} %), "
          f"latency p50 {ms(v['p50_us'])}, p99 {ms(v['p99_us'])}, max {ms(v['max_us'])}")
print(f"counts: 200 {count('200')}, 429 {count('429')}, 503 {count('503')}, 5xx {n5xx}, "
      f"other {other or 0}; share of 429 {100 * count('429') / max(answered, 1):.1f} %")
print(f"lost (wrk connect {e['connect']}, read {e['read']}, write {e['write']}, "
      f"timeout {e['timeout']}): {lost}; wrk non-2xx/3xx {e['status']}")
print(f"RSS: {len(kbs)} samples, min {mib(min(kbs, default=0)):.1f} MiB, "
      f"peak sampled {mib(max(kbs, default=0)):.1f} MiB, VmHWM {mib(hwm_kb):.1f} MiB; "
      f"mean of the first 10 s {mib(raw_first):.1f} MiB, of the last 10 s {mib(raw_last):.1f} MiB; "
      f"after a {ramp} s ramp-up, first {win} s {mib(first):.1f} MiB vs last {win} s "
      f"{mib(last):.1f} MiB ({100 * growth:+.1f} %): {'flat' if flat else 'GROWING'}")
fits_observed = int(delta("multifit_embed_duration_seconds_count"))
overloaded = int(delta('multifit_rejections_total{reason="overloaded"}'))
print(f"/metrics for the run: /v1/fit by status {dict(sorted(server_status.items()))}, "
      f"rejections overloaded {overloaded}, fits completed {fits_observed}")
mismatch = {s: server_status.get(s, 0) - count(s) for s in set(server_status) | set(statuses)
            if server_status.get(s, 0) != count(s)}
if mismatch:
    print(f"note: /metrics minus wrk by status {mismatch} (answers in flight when wrk stopped, "
          f"at most {connections})")

summary = {"points": n, "seconds": secs, "answers_per_s": answered / secs,
           "fits_per_s": count("200") / secs, "wrk": w, "lost": lost, "count_5xx": n5xx,
           "server_status": server_status, "server_5xx": server_5xx,
           "rejections_overloaded": overloaded, "fits_completed": fits_observed,
           "rss_kb": rss, "vm_hwm_kb": hwm_kb, "rss_first10_kb": raw_first, "rss_last10_kb": raw_last,
           "rss_ramp_s": ramp, "rss_steady_first_kb": first, "rss_steady_last_kb": last,
           "rss_flat": flat, "server_alive": alive}
(d / "summary.json").write_text(json.dumps(summary, indent=1))

failures = []
if n5xx or server_5xx:
    failures.append(f"{n5xx} 5xx answers seen by wrk, {server_5xx} counted by the server")
if lost:
    failures.append(f"{lost} requests lost without an answer")
if not alive:
    failures.append("server died")
if abs(sum(mismatch.values())) > connections:
    failures.append(f"/metrics and wrk disagree by more than {connections}: {mismatch}")
for f in failures:
    print(f"FAIL - {f}")
if not flat:
    print("warning: RSS grew by more than 10 % between the first and the last seconds after the ramp-up")
sys.exit(1 if failures else 0)
PY
  summaries+=("$dir/summary.json")
  echo
done

echo "summaries: ${summaries[*]}"
exit "$status"
