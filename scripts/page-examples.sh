#!/usr/bin/env bash
# Regenerates the examples compiled into the page at / (src/api/page/examples/*.json), each a
# POST /v1/fit body with geometric refinement on: the LCE set of the README (multifit-train gen-lce, seed 9, scale 2: a line,
# two ellipses and a circle, 50 points each), KT3DMoSeg Seq059_Clip01 frames 1-5 and the
# AdelaideRMF pair breadcartoychips, and the pair bonython as if its second photo came from a
# camera of 1.5 times the resolution (each image's size sent), from ../shared/datasets (credits:
# its README and the page).
set -euo pipefail
cd "$(dirname "$0")/.."
out=src/api/page/examples
datasets=${DATASETS:-../shared/datasets}
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
cargo build --release --bin multifit-train
./target/release/multifit-train gen-lce --out "$tmp" --count 1 --seed 9 --scale 2 >/dev/null
python3 - "$tmp"/lce-*.json "$datasets" "$out" <<'PY'
import json, sys

lce, datasets, out = sys.argv[1:4]

def write(name, body, decimals):
    body["points"] = [[round(v, decimals) for v in row] for row in body["points"]]
    with open(f"{out}/{name}.json", "w") as f:
        json.dump(body, f, separators=(",", ":"))
        f.write("\n")

src = json.load(open(lce))
write("lce", {"kind": "points2d", "model": "lce", "refine": True, "points": src["points"]}, 4)
for name, model, path in [
    ("kt3dmoseg", "kt3dmoseg", "kt3dmoseg_first5/Seq059_Clip01.json"),
    ("adelaidermf", "adelaide-fundamental", "adelaidermf/breadcartoychips.json"),
]:
    src = json.load(open(f"{datasets}/{path}"))
    write(name, {"kind": src["kind"], "model": model, "refine": True,
                 "image_size": src["image_size"], "points": src["points"]}, 2)
src = json.load(open(f"{datasets}/adelaidermf/bonython.json"))
(w, h), f = src["image_size"], 1.5
write("two-cameras", {"kind": "correspondences", "model": "adelaide-homography", "refine": True,
                      "image_size": [[w, h], [f * w, f * h]],
                      "points": [[x1, y1, f * x2, f * y2] for x1, y1, x2, y2 in src["points"]]}, 2)
PY
ls -l "$out"
