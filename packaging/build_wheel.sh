#!/usr/bin/env bash
# Build the wheel and the sdist, install the wheel into a FRESH virtual
# environment and smoke-test it from outside the checkout; print the figures.
#
#   bash packaging/build_wheel.sh                # build, install, smoke-test
#   bash packaging/build_wheel.sh --smoke-only   # smoke-test the venv there is
#
# Steps: `python -m build` (sdist, then the wheel from the sdist) into dist/;
# a new venv with `pip install dist/*.whl -c packaging/constraints.txt`; then,
# in an empty temporary folder with an empty platform cache (XDG_CACHE_HOME):
# `workbench --version`, `workbench samples list` (the NLM credit line),
# `workbench demo` headless (no DISPLAY), and the window under its own Xvfb
# (xvfb-run) with a screenshot.  Checks that the package and its data tables
# are imported from the venv, that the reference heads were cached in the
# platform cache folder and that nothing was written into the installed package
# (but __pycache__: Python's bytecode and numba's compiled animation kernels,
# which numba keeps beside a writable module; a read-only install sends them
# to ~/.cache/numba).
#
# Environment (all optional):
#   WORKBENCH_TOOLS_VENV  venv with the build tools (default build/tools-venv;
#                         made and filled from packaging/pyinstaller/requirements.txt)
#   WORKBENCH_WHEEL_VENV  the fresh venv (default build/wheel-venv; REMOVED first)
#   WORKBENCH_SAMPLE_MIRRORS  local sample mirror (default ../shared/data when present)
#   WORKBENCH_SMOKE_DIR   where the demo output and the screenshot go
#                         (default build/smoke/wheel; replaced)
# Needs Python >= 3.11 (PYTHON, default python3) and xvfb-run for the window.
set -euo pipefail
cd "$(dirname "$0")/.."
root="$(pwd)"
py="${PYTHON:-python3}"
tools="${WORKBENCH_TOOLS_VENV:-$root/build/tools-venv}"
venv="${WORKBENCH_WHEEL_VENV:-$root/build/wheel-venv}"
smoke="${WORKBENCH_SMOKE_DIR:-$root/build/smoke/wheel}"
constraints="$root/packaging/constraints.txt"
if [ -z "${WORKBENCH_SAMPLE_MIRRORS:-}" ] && [ -d "$root/../shared/data" ]; then
  export WORKBENCH_SAMPLE_MIRRORS="$(cd "$root/../shared/data" && pwd)"
fi

now() { date +%s.%N; }
since() { awk -v a="$1" -v b="$(now)" 'BEGIN { printf "%.1f", b - a }'; }
fail() { echo "build_wheel: FAILED: $*" >&2; exit 1; }
mib() { awk -v b="$(stat -c %s "$1")" 'BEGIN { printf "%.2f MiB", b / 1048576 }'; }

mkdir -p build
build=1
case "${1:-}" in
  "") ;;
  --smoke-only) build=0 ;;
  *) echo "usage: bash packaging/build_wheel.sh [--smoke-only]" >&2; exit 64 ;;
esac
build_s="n/a" install_s="n/a (not reinstalled)"

build_all() {
# ------------------------------------------------------------------ build tools
if [ ! -x "$tools/bin/python" ]; then
  "$py" -m venv "$tools"
fi
"$tools/bin/python" -m pip install -q -r packaging/pyinstaller/requirements.txt > build/pip-tools.log 2>&1 \
  || { tail -20 build/pip-tools.log; fail "pip install of the build tools (log: build/pip-tools.log)"; }

# ------------------------------------------------------------------ wheel + sdist
version="$("$tools/bin/python" -c 'import tomllib; print(tomllib.load(open("pyproject.toml", "rb"))["project"]["version"])')"
rm -f dist/forensic_workbench-"$version"-*.whl dist/forensic_workbench-"$version".tar.gz
t0="$(now)"
"$tools/bin/python" -m build --outdir dist . > build/build-wheel.log 2>&1 \
  || { tail -30 build/build-wheel.log; fail "python -m build (log: build/build-wheel.log)"; }
build_s="$(since "$t0")"
wheel="$root/dist/forensic_workbench-$version-py3-none-any.whl"
sdist="$root/dist/forensic_workbench-$version.tar.gz"
[ -f "$wheel" ] && [ -f "$sdist" ] || fail "no wheel or sdist in dist/"
# the wheel (built from the sdist) must carry the data tables and package data
"$tools/bin/python" - "$wheel" "$root/data_tables" <<'EOF' || fail "the wheel lacks package data"
import sys, zipfile
from pathlib import Path
names = set(zipfile.ZipFile(sys.argv[1]).namelist())
tables = Path(sys.argv[2])
want = {f"workbench/_data/data_tables/{p.relative_to(tables).as_posix()}"
        for p in tables.rglob("*") if p.is_file()}
want |= {"workbench/io/sample_registry.json", "workbench/resources/forensic-workbench.png"}
missing = sorted(want - names)
if missing:
    sys.exit("missing from the wheel: " + ", ".join(missing[:10]))
EOF

# ------------------------------------------------------------------ fresh venv
rm -rf "$venv"
"$py" -m venv "$venv"
t0="$(now)"
"$venv/bin/python" -m pip install -q "$wheel" -c "$constraints" > build/install-wheel.log 2>&1 \
  || { tail -30 build/install-wheel.log; fail "pip install of the wheel"; }
install_s="$(since "$t0")"
}

version="$("$py" -c 'import tomllib; print(tomllib.load(open("pyproject.toml", "rb"))["project"]["version"])')"
wheel="$root/dist/forensic_workbench-$version-py3-none-any.whl"
sdist="$root/dist/forensic_workbench-$version.tar.gz"
if [ "$build" = 1 ]; then
  build_all
fi
[ -x "$venv/bin/workbench" ] || fail "no $venv/bin/workbench (build first)"

# ------------------------------------------------------------------ smoke tests
rm -rf "$smoke"
mkdir -p "$smoke"
work="$(mktemp -d)"
trap 'rm -rf "$work"' EXIT
mkdir -p "$work/run" "$work/cache"
cd "$work/run"
unset PYTHONPATH WORKBENCH_DATA_DIR
export XDG_CACHE_HOME="$work/cache" QT_API=pyside6
site="$("$venv/bin/python" -c 'import pathlib, workbench; print(pathlib.Path(workbench.__file__).parent)')"
case "$site" in "$venv"/*) ;; *) fail "workbench imported from $site, not from the venv" ;; esac
tables="$("$venv/bin/python" -c 'from workbench.core.data_paths import data_tables_dir; print(data_tables_dir())')"
[ "$tables" = "$site/_data/data_tables" ] || fail "data tables read from $tables"
package_files() { find "$site" -type f -not -path "*/__pycache__/*" -printf '%P %s %T@\n' | sort | sha256sum; }
before="$(package_files)"

got="$("$venv/bin/workbench" --version)"
[ "$got" = "workbench $version" ] || fail "--version said '$got'"
"$venv/bin/workbench" samples list > "$work/samples.txt" || fail "workbench samples list"
grep -q "Courtesy of the U.S. National Library of Medicine" "$work/samples.txt" \
  || fail "samples list shows no NLM credit"

t0="$(now)"
env -u DISPLAY -u WAYLAND_DISPLAY "$venv/bin/workbench" demo --out "$smoke/demo_out" > "$smoke/demo.log" 2>&1 \
  || { tail -20 "$smoke/demo.log"; fail "workbench demo"; }
demo_s="$(since "$t0")"
[ -f "$smoke/demo_out/summary.json" ] || fail "the demo wrote no summary.json"
ls "$XDG_CACHE_HOME"/forensic-workbench/templates/male-*/template.json > /dev/null 2>&1 \
  || fail "no reference head cached under $XDG_CACHE_HOME/forensic-workbench/templates"

window_s="n/a"
if command -v xvfb-run > /dev/null 2>&1; then
  t0="$(now)"
  QT_QPA_PLATFORM=xcb xvfb-run -a -s "-screen 0 1600x1200x24" \
    "$venv/bin/workbench" gui --expression smile --screenshot "$smoke/window.png" \
    > "$smoke/window.log" 2>&1 || { cat "$smoke/window.log"; fail "workbench gui"; }
  window_s="$(since "$t0")"
  [ -s "$smoke/window.png" ] || fail "no screenshot"
  if grep -qi "error" "$smoke/window.log"; then cat "$smoke/window.log"; fail "the window reported an error"; fi
else
  echo "xvfb-run not found: window not tested (apt-get install xvfb xauth)" >&2
fi
after="$(package_files)"
[ "$before" = "$after" ] || fail "files were written into the installed package $site"
stray="$(ls -A "$work/run")"
[ -z "$stray" ] || fail "files left in the working folder: $stray"

echo "wheel:   $wheel ($(mib "$wheel"))"
echo "sdist:   $sdist ($(mib "$sdist"))"
echo "figures: build ${build_s} s, install ${install_s} s (fresh venv, local package cache), \
demo ${demo_s} s (empty cache: reference heads built), window ${window_s} s"
echo "installed size: $(du -sh "$venv" | cut -f1) (the whole venv)"
echo "screenshot: $smoke/window.png; demo: $smoke/demo_out"
