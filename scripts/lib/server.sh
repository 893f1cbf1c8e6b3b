# Shared by the scripts that run their own multifit-server (source it; needs bash and curl).
#
#   start_server LOG_DIR BINARY [SERVER_ARGS...]  starts BINARY with SERVER_ARGS (give --addr with
#       port 0 for an ephemeral port), logs to LOG_DIR/server.{out,log}, and returns once
#       /health/ready answers 200, with $server_pid and $base (http://127.0.0.1:PORT) set; exits 2
#       when the server does not start or never becomes ready.
#   stop_server   SIGTERM, up to 30 s to drain, then SIGKILL; clears $server_pid.

server_pid=
base=

start_server() {
  local dir=$1 binary=$2
  shift 2
  "$binary" "$@" > "$dir/server.out" 2> "$dir/server.log" &
  server_pid=$!
  base=
  for _ in $(seq 300); do
    base=$(sed -n 's/^multifit-server listening on \(http:\/\/[^ ]*\)$/\1/p' "$dir/server.out")
    [ -n "$base" ] && break
    kill -0 "$server_pid" 2>/dev/null || break
    sleep 0.1
  done
  [ -n "$base" ] || { echo "server did not start; see $dir/server.log" >&2; exit 2; }
  for _ in $(seq 600); do
    [ "$(curl -s -o /dev/null -w '%{http_code}' "$base/health/ready")" = 200 ] && return 0
    kill -0 "$server_pid" 2>/dev/null || break
    sleep 0.2
  done
  echo "server at $base never became ready; see $dir/server.log" >&2
  exit 2
}

stop_server() {
  [ -n "$server_pid" ] || return 0
  kill -TERM "$server_pid" 2>/dev/null || true
  for _ in $(seq 300); do
    kill -0 "$server_pid" 2>/dev/null || break
    sleep 0.1
  done
  kill -KILL "$server_pid" 2>/dev/null || true
  wait "$server_pid" 2>/dev/null || true
  server_pid=
}
