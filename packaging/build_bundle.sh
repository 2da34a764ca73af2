#!/usr/bin/env bash
# Build the Linux one-folder desktop bundle with PyInstaller and smoke-test it.
#
#   bash packaging/build_bundle.sh                # build, then smoke-test
#   bash packaging/build_bundle.sh --smoke-only   # smoke-test the dist/workbench/ there is
#
# Output: dist/workbench/ -- the executable dist/workbench/workbench (the
# command line with arguments, the window without), its libraries in
# _internal/, and install_desktop_entry.sh + workbench.desktop for the menu
# entry and icon (see packaging/README.md).  Copy or tar the folder anywhere;
# it needs no Python and no checkout.
#
# Steps: the wheel is built (python -m build --wheel) and installed with the
# pinned dependencies into the tools venv together with the pinned PyInstaller
# (packaging/pyinstaller/requirements.txt); PyInstaller runs the spec
# packaging/pyinstaller/workbench.spec from an empty folder outside the
# checkout, so what is bundled is the installed wheel.  Smoke tests, from an
# empty temporary folder with an empty platform cache (XDG_CACHE_HOME), no
# PYTHONPATH and the checkout nowhere on the path:
#   workbench --version (timed twice: first and warm start), samples list,
#   the demo headless (no DISPLAY), the window under its own Xvfb showing the
#   reference head smiling (Animate tool: reference head, numba, VTK, Qt) with
#   a screenshot; checks that the reference heads were cached in the platform
#   cache folder with the same key as a pip install, and that no file of the
#   checkout was opened (strace, when installed) by --version and samples list.
#
# Environment (all optional):
#   WORKBENCH_TOOLS_VENV  venv with the build tools and the wheel (default build/tools-venv)
#   WORKBENCH_SAMPLE_MIRRORS  local sample mirror (default ../shared/data when present)
#   WORKBENCH_SMOKE_DIR   demo output and screenshot (default build/smoke/bundle; replaced)
set -euo pipefail
cd "$(dirname "$0")/.."
root="$(pwd)"
py="${PYTHON:-python3}"
tools="${WORKBENCH_TOOLS_VENV:-$root/build/tools-venv}"
smoke="${WORKBENCH_SMOKE_DIR:-$root/build/smoke/bundle}"
constraints="$root/packaging/constraints.txt"
bundle="$root/dist/workbench"
if [ -z "${WORKBENCH_SAMPLE_MIRRORS:-}" ] && [ -d "$root/../shared/data" ]; then
  export WORKBENCH_SAMPLE_MIRRORS="$(cd "$root/../shared/data" && pwd)"
fi

now() { date +%s.%N; }
since() { awk -v a="$1" -v b="$(now)" 'BEGIN { printf "%.1f", b - a }'; }
fail() { echo "build_bundle: FAILED: $*" >&2; exit 1; }
mkdir -p build
build=1
case "${1:-}" in
  "") ;;
  --smoke-only) build=0 ;;
  *) echo "usage: bash packaging/build_bundle.sh [--smoke-only]" >&2; exit 64 ;;
esac

# ------------------------------------------------------------------ tools + the wheel
build_all() {
  if [ ! -x "$tools/bin/python" ]; then
    "$py" -m venv "$tools"
  fi
  "$tools/bin/python" -m pip install -q -r packaging/pyinstaller/requirements.txt > build/pip-tools.log 2>&1 \
    || { tail -20 build/pip-tools.log; fail "pip install of the build tools (log: build/pip-tools.log)"; }
  version="$("$tools/bin/python" -c 'import tomllib; print(tomllib.load(open("pyproject.toml", "rb"))["project"]["version"])')"
  wheel="$root/dist/forensic_workbench-$version-py3-none-any.whl"
  rm -f "$wheel"
  "$tools/bin/python" -m build --wheel --outdir dist . > build/build-bundle-wheel.log 2>&1 \
    || { tail -30 build/build-bundle-wheel.log; fail "python -m build --wheel"; }
  "$tools/bin/python" -m pip uninstall -q -y forensic-workbench > /dev/null 2>&1 || true
  "$tools/bin/python" -m pip install -q "$wheel" -c "$constraints" > build/pip-bundle.log 2>&1 \
    || { tail -20 build/pip-bundle.log; fail "pip install of the wheel into $tools (log: build/pip-bundle.log)"; }
  "$tools/bin/python" -m pip check > /dev/null || fail "pip check in $tools"

  # ------------------------------------------------------------------ PyInstaller
  rm -rf "$bundle"
  spec_work="$root/build/pyinstaller"
  rm -rf "$spec_work"
  mkdir -p "$spec_work/cwd"
  t0="$(now)"
  (cd "$spec_work/cwd" && env -u PYTHONPATH "$tools/bin/pyinstaller" --noconfirm --log-level WARN \
    --distpath "$root/dist" --workpath "$spec_work" "$root/packaging/pyinstaller/workbench.spec") \
    > build/pyinstaller.log 2>&1 || { tail -30 build/pyinstaller.log; fail "pyinstaller (log: build/pyinstaller.log)"; }
  bundle_s="$(since "$t0")"
  [ -x "$bundle/workbench" ] || fail "no $bundle/workbench"
  install -m 755 packaging/linux/install_desktop_entry.sh "$bundle/install_desktop_entry.sh"
  install -m 644 packaging/linux/workbench.desktop "$bundle/workbench.desktop"
}

version="$("$py" -c 'import tomllib; print(tomllib.load(open("pyproject.toml", "rb"))["project"]["version"])')"
bundle_s="n/a (not rebuilt)"
if [ "$build" = 1 ]; then
  build_all
fi
[ -x "$bundle/workbench" ] || fail "no $bundle/workbench (build it first)"

# ------------------------------------------------------------------ smoke tests
rm -rf "$smoke"
mkdir -p "$smoke"
work="$(mktemp -d)"
trap 'rm -rf "$work"' EXIT
mkdir -p "$work/run" "$work/cache"
cd "$work/run"
unset PYTHONPATH PYTHONHOME WORKBENCH_DATA_DIR QT_API
export XDG_CACHE_HOME="$work/cache"
exe="$bundle/workbench"

t0="$(now)"
got="$("$exe" --version)"
first_s="$(since "$t0")"
[ "$got" = "workbench $version" ] || fail "--version said '$got'"
t0="$(now)"
"$exe" --version > /dev/null
warm_s="$(since "$t0")"
if command -v strace > /dev/null 2>&1; then
  strace -f -qq -e trace=open,openat,stat,newfstatat,execve -o "$work/trace" \
    "$exe" samples list > "$work/samples.txt"
  # any file or folder of the checkout, other than the bundle and the folders above it
  grep -v ENOENT "$work/trace" | grep -o '"/[^"]*"' | tr -d '"' | sort -u \
    | awk -v root="$root/" -v bundle="$bundle" \
      'index($0, root) == 1 && $0 != bundle && index($0, bundle "/") != 1 \
       && index(bundle "/", $0 "/") != 1' > "$work/checkout"
  if [ -s "$work/checkout" ]; then
    head -5 "$work/checkout" >&2
    fail "the bundle opened files of the checkout"
  fi
else
  "$exe" samples list > "$work/samples.txt"
fi
grep -q "Courtesy of the U.S. National Library of Medicine" "$work/samples.txt" \
  || fail "samples list shows no NLM credit"

t0="$(now)"
env -u DISPLAY -u WAYLAND_DISPLAY "$exe" demo --out "$smoke/demo_out" > "$smoke/demo.log" 2>&1 \
  || { tail -20 "$smoke/demo.log"; fail "workbench demo"; }
demo_s="$(since "$t0")"
[ -f "$smoke/demo_out/summary.json" ] || fail "the demo wrote no summary.json"
# the cached heads carry the same key as a pip install of this release
key="$(cd "$work" && "$tools/bin/python" -c 'from workbench.services.templates.cache import source_key; print(source_key())')"
for sex in male female; do
  [ -f "$XDG_CACHE_HOME/forensic-workbench/templates/$sex-$key/template.json" ] \
    || fail "no $sex reference head cached as $XDG_CACHE_HOME/forensic-workbench/templates/$sex-$key"
done

window_s="n/a"
if command -v xvfb-run > /dev/null 2>&1; then
  t0="$(now)"
  QT_QPA_PLATFORM=xcb xvfb-run -a -s "-screen 0 1600x1200x24" \
    "$exe" gui --expression smile --screenshot "$smoke/window.png" > "$smoke/window.log" 2>&1 \
    || { cat "$smoke/window.log"; fail "workbench gui"; }
  window_s="$(since "$t0")"
  [ -s "$smoke/window.png" ] || fail "no screenshot"
  if grep -qi "error" "$smoke/window.log"; then cat "$smoke/window.log"; fail "the window reported an error"; fi
else
  echo "xvfb-run not found: window not tested (apt-get install xvfb xauth)" >&2
fi
stray="$(ls -A "$work/run")"
[ -z "$stray" ] || fail "files left in the working folder: $stray"
caches="$(cd "$XDG_CACHE_HOME" && ls -d -- * | tr '\n' ' ')"

echo "bundle:  $bundle ($(du -sh "$bundle" | cut -f1) on disk, $(find "$bundle" -type f | wc -l) files)"
echo "figures: PyInstaller ${bundle_s} s; --version ${first_s} s first, ${warm_s} s warm; \
demo ${demo_s} s (empty cache: reference heads built); window ${window_s} s"
echo "caches written under \$XDG_CACHE_HOME: $caches"
echo "screenshot: $smoke/window.png; demo: $smoke/demo_out"
