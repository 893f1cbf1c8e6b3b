#!/usr/bin/env bash
# Regenerates the pictures in docs/: one SVG fit of each kind in docs/pictures/ (POST /v1/fit with
# `Accept: image/svg+xml` on the page's bundled examples: points2d from LCE, correspondences from
# the AdelaideRMF pair, trajectories from the KT3DMoSeg clip) and docs/page.png, the page at /
# after fitting the LCE example, in headless Chromium at 1280 x 900.
#
# Needs curl and chromium (Debian: apt-get install -y --no-install-recommends chromium).
set -euo pipefail
cd "$(dirname "$0")/.."
cargo build --release --bin multifit-server
mkdir -p docs/pictures
log=$(mktemp)
profile=$(mktemp -d)
./target/release/multifit-server --addr 127.0.0.1:0 --models models >"$log" 2>&1 &
server=$!
trap 'kill "$server" 2>/dev/null || true; rm -rf "$profile" "$log"' EXIT

addr=
for _ in $(seq 300); do
  addr=$(grep -o 'http://[0-9.:]*' "$log" | head -n 1 || true)
  [ -n "$addr" ] && curl -sf "$addr/health/ready" >/dev/null && break
  sleep 0.1
done
curl -sf "$addr/health/ready" >/dev/null || { echo "the server did not start:" >&2; cat "$log" >&2; exit 1; }

for pair in points2d:lce correspondences:adelaidermf trajectories:kt3dmoseg; do
  kind=${pair%%:*}
  name=${pair#*:}
  curl -sf "$addr/examples/$name.json" |
    curl -sf "$addr/v1/fit" -H 'content-type: application/json' -H 'accept: image/svg+xml' \
      --data-binary @- -o "docs/pictures/$kind-$name.svg"
  echo "docs/pictures/$kind-$name.svg: $(grep -o 'class="pt"' "docs/pictures/$kind-$name.svg" | wc -l) marks"
done

chromium --headless --no-sandbox --disable-gpu --disable-quic --no-first-run \
  --disable-background-networking --disable-component-update --disable-sync \
  --user-data-dir="$profile" --hide-scrollbars --window-size=1280,900 \
  --virtual-time-budget=60000 --screenshot="$PWD/docs/page.png" "$addr/?example=lce&fit=1" 2>/dev/null
echo "docs/page.png"
