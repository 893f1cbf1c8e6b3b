#!/usr/bin/env bash
# Checks the claim of src/api/routes.rs run_fit: "If the client goes away while queued, this
# future is dropped and the fit never runs."
#
#   scripts/check-abandoned.sh [--server PATH] [--workers W] [--abandon M]
#
# It starts its own server (W workers, default 2; queue capacity 32) on an ephemeral 127.0.0.1
# port, fills the workers and the queue with slow fits (N = 20000) from clients that wait for
# their answers, then sends M (default 8) small fits (N = 1000) from clients that give up after
# --max-time seconds, so the small fits are admitted, queued behind the slow ones and abandoned.
# Round A gives up after 0.05 s; round B after 0.5 s, reading multifit_queue_depth meanwhile to
# prove the small fits had been admitted. A fit that is computed with its future alive is recorded
# in multifit_points_per_request (bucket le="1000" for the small ones), multifit_queue_duration
# and multifit_requests_total; so the claim holds when, after every slow fit has finished, the
# le="1000" bucket did not move. Round C abandons fits already running on the workers (which
# spawn_blocking cannot stop) and times a small fit sent right after, which shows whether the
# workers kept computing for nobody.
#
# Exits 1 when an abandoned queued fit was computed or a slow fit failed, 2 on a set-up problem.
# Needs curl and python3; bodies from scripts/loadtest-body.py (data in $MULTIFIT_DATA).
set -euo pipefail

root=$(cd "$(dirname "$0")/.." && pwd)
server=$root/target/release/multifit-server
workers=2
abandon=8
while [ $# -gt 0 ]; do
  case $1 in
    --server) server=$2; shift 2 ;;
    --workers) workers=$2; shift 2 ;;
    --abandon) abandon=$2; shift 2 ;;
    -h|--help) sed -n '2,/^set -euo/{/^set -euo/d;s/^# \{0,1\}//;p}' "$0"; exit 0 ;;
    *) echo "unknown argument $1 (see --help)" >&2; exit 2 ;;
  esac
done
[ -x "$server" ] || { echo "no server binary at $server (cargo build --release)" >&2; exit 2; }

tmp=$(mktemp -d)
# shellcheck source=scripts/lib/server.sh
source "$root/scripts/lib/server.sh"
cleanup() {
  if [ -n "$server_pid" ]; then kill "$server_pid" 2>/dev/null || true; fi
  rm -rf "$tmp"
}
trap cleanup EXIT
python3 "$root/scripts/loadtest-body.py" 20000 "$tmp/slow.json"
python3 "$root/scripts/loadtest-body.py" 1000 "$tmp/small.json"

start_server "$tmp" "$server" --addr 127.0.0.1:0 --models "$root/models" --workers "$workers" \
  --queue-capacity 32

# fit BODY [CURL_ARGS...]: prints "status seconds".
fit() {
  local body=$1
  shift
  curl -s -o /dev/null -w '%{http_code} %{time_total}\n' -H 'content-type: application/json' \
    --data-binary "@$body" "$@" "$base/v1/fit" || true
}
# metric SERIES: the value of one exact series (name and labels) in /metrics, 0 when absent.
metric() {
  curl -s "$base/metrics" | awk -v s="$1" '$1 == s {v = $2} END {print v + 0}'
}
depth() { metric multifit_queue_depth; }
small_fits() { metric 'multifit_points_per_request_bucket{le="1000"}'; }
all_fits() { metric multifit_points_per_request_count; }
started() { metric multifit_queue_duration_seconds_count; }
fit_200() { metric 'multifit_requests_total{endpoint="/v1/fit",status="200"}'; }
# fit_any: /v1/fit requests counted with any status.
fit_any() {
  curl -s "$base/metrics" | awk 'index($1, "multifit_requests_total{endpoint=\"/v1/fit\",") == 1 {v += $2} END {print v + 0}'
}

read -r s t_slow < <(fit "$tmp/slow.json" --max-time 300)
read -r s2 t_small < <(fit "$tmp/small.json" --max-time 300)
echo "# server at $base, $workers workers; alone: N = 20000 fit $s in $t_slow s, N = 1000 fit $s2 in $t_small s"
if [ "$s" != 200 ] || [ "$s2" != 200 ]; then
  echo "warm-up fits failed" >&2
  exit 2
fi

status=0
slow_count=$((workers + 2))
# round NAME MAX_TIME: slow live fits fill the workers and part of the queue, then $abandon small
# fits give up after MAX_TIME seconds.
round() {
  local name=$1 max_time=$2 i
  local small0 all0 started0 ok0 any0 admitted=n/a after_abandon slow_ok=0
  small0=$(small_fits); all0=$(all_fits); started0=$(started); ok0=$(fit_200); any0=$(fit_any)
  local slow_pids=() pids=()
  for i in $(seq "$slow_count"); do
    fit "$tmp/slow.json" --max-time 300 > "$tmp/answer-slow.$i" &
    slow_pids+=($!)
  done
  for _ in $(seq 200); do
    [ "$(depth)" -ge "$slow_count" ] && break
    sleep 0.05
  done
  for i in $(seq "$abandon"); do
    fit "$tmp/small.json" --max-time "$max_time" > "$tmp/answer-small.$i" &
    pids+=($!)
  done
  if [ "$(echo "$max_time >= 0.2" | bc)" = 1 ]; then
    sleep "$(echo "$max_time / 2" | bc -l)"
    admitted=$(depth)
  fi
  wait "${pids[@]}"
  sleep 0.2
  after_abandon=$(depth)
  wait "${slow_pids[@]}"
  for i in $(seq "$slow_count"); do
    [ "$(cut -d' ' -f1 "$tmp/answer-slow.$i")" = 200 ] && slow_ok=$((slow_ok + 1))
  done
  for _ in $(seq 100); do
    [ "$(depth)" = 0 ] && break
    sleep 0.1
  done
  sleep 1
  local small_done=$(($(small_fits) - small0)) all_done=$(($(all_fits) - all0))
  local started_n=$(($(started) - started0)) ok_n=$(($(fit_200) - ok0)) any_n=$(($(fit_any) - any0))
  local gave_up
  gave_up=$(cat "$tmp"/answer-small.* | awk '$1 == "000"' | wc -l)
  echo "round $name: $slow_count slow fits (live clients), then $abandon small fits abandoned after $max_time s"
  echo "  small clients that gave up without an answer: $gave_up of $abandon"
  echo "  queue depth while the small clients waited: $admitted (slow $slow_count + small $abandon if admitted);" \
    "0.2 s after they gave up: $after_abandon"
  echo "  slow fits answered 200: $slow_ok of $slow_count"
  echo "  /metrics deltas: fits given a worker $started_n, fits completed $all_done" \
    "(N <= 1000: $small_done), /v1/fit 200 $ok_n, /v1/fit any status $any_n"
  if [ "$slow_ok" != "$slow_count" ]; then
    echo "  FAIL - a slow fit with a live client did not answer 200"
    status=1
  fi
  if [ "$small_done" -gt 0 ]; then
    echo "  FAIL - $small_done abandoned queued fits were computed"
    status=1
  elif [ "$gave_up" != "$abandon" ]; then
    echo "  inconclusive - only $gave_up of $abandon small clients gave up before an answer"
  else
    echo "  ok - no abandoned queued fit was computed"
  fi
  rm -f "$tmp"/answer-*
}

round A 0.05
round B 0.5

# Round C: abandon fits while they run, then time a small fit sent at once.
started0=$(started)
pids=()
for i in $(seq "$workers"); do
  fit "$tmp/slow.json" --max-time "$(echo "$t_slow / 3" | bc -l)" > /dev/null &
  pids+=($!)
done
wait "${pids[@]}"
depth_c=$(depth)
read -r s_probe t_probe < <(fit "$tmp/small.json" --max-time 300)
echo "round C: $workers slow fits abandoned after $(printf '%.2f' "$(echo "$t_slow / 3" | bc -l)") s" \
  "(while running); queue depth just after: $depth_c"
echo "  a small fit sent right after: status $s_probe in $t_probe s (alone: $t_small s)"
if [ "$(echo "$t_probe > $t_small + $t_slow / 3" | bc -l)" = 1 ]; then
  echo "  so the workers went on computing the abandoned running fits (spawn_blocking cannot be" \
    "stopped; their permits are held until they end)"
  [ "$depth_c" = 0 ] && echo "  and multifit_queue_depth read 0 while they ran: the gauge does not count them"
else
  echo "  so the workers were free at once: the abandoned running fits were stopped"
fi
echo "  fits given a worker in round C: $(($(started) - started0)) (the abandoned ones and the probe)"

stop_server
exit "$status"
