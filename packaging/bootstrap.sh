#!/usr/bin/env bash
# Set up the workbench on a fresh Debian/Ubuntu machine and run one job.
#
#   bash packaging/bootstrap.sh demo    # install, then run the main job on the default case
#   bash packaging/bootstrap.sh test    # install (with test tools), then run the whole test suite
#
# Needs Python >= 3.11 with venv.  System libraries for off-screen and Qt
# rendering (and Xvfb for the GUI tests) come from apt: installed when run as
# root, otherwise the exact apt-get line is printed and the script stops.
# The virtual environment lives in .venv (override with WORKBENCH_VENV) and
# is reused while pyproject.toml and packaging/constraints.txt are unchanged.
# Every Python package is installed at the version pinned in
# packaging/constraints.txt (the versions CI passes with); to move to newer
# releases run packaging/update_constraints.sh.
set -euo pipefail

mode="${1:-}"
case "$mode" in
  demo|test) ;;
  *) echo "usage: bash packaging/bootstrap.sh demo|test" >&2; exit 64 ;;
esac
shift || true

cd "$(dirname "$0")/.."
root="$(pwd)"

# --------------------------------------------------------------- system packages
apt_pkgs="python3-venv xvfb xauth libgl1 libegl1 libglx-mesa0 libgl1-mesa-dri libegl-mesa0 \
libxkbcommon-x11-0 libxcb-icccm4 libxcb-keysyms1 libxcb-cursor0 libxcb-image0 libxcb-randr0 \
libxcb-render-util0 libxcb-shape0 libxcb-xfixes0 libxcb-xkb1 libxcb-sync1 libxcb-shm0 \
libx11-xcb1 libxrender1 libxext6 libsm6 libice6 libfontconfig1 fonts-dejavu-core libdbus-1-3 \
poppler-utils"
if command -v dpkg >/dev/null 2>&1; then
  missing=""
  for p in $apt_pkgs; do dpkg -s "$p" >/dev/null 2>&1 || missing="$missing $p"; done
  if [ -n "$missing" ]; then
    if [ "$(id -u)" = "0" ]; then
      echo "installing system packages:$missing"
      export DEBIAN_FRONTEND=noninteractive
      apt-get update -qq >/dev/null
      apt-get install -y -qq --no-install-recommends $missing >/dev/null
    else
      echo "missing system packages; run this once, then rerun:" >&2
      echo "  sudo apt-get install -y --no-install-recommends$missing" >&2
      exit 1
    fi
  fi
fi

# the tests check exported glTF files with the Khronos glTF-Validator (an npm package,
# installed by the test into a cache folder): it needs node and npm
if [ "$mode" = test ] && ! { command -v node >/dev/null 2>&1 && command -v npm >/dev/null 2>&1; }; then
  if [ "$(id -u)" = "0" ] && command -v apt-get >/dev/null 2>&1; then
    echo "installing system packages: nodejs npm (glTF validation in the tests)"
    DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends nodejs npm \
      >/dev/null || echo "could not install nodejs/npm: the glTF validation test will skip" >&2
  else
    echo "node/npm not found: the glTF validation test will skip" >&2
  fi
fi

# --------------------------------------------------------------- python environment
py="${PYTHON:-python3}"
if ! "$py" -c 'import sys; sys.exit(0 if sys.version_info >= (3, 11) else 1)'; then
  echo "Python >= 3.11 is needed ($py is $("$py" --version 2>&1))" >&2
  exit 1
fi
venv="${WORKBENCH_VENV:-$root/.venv}"
extras="$([ "$mode" = test ] && echo "[test]" || echo "")"
constraints="$root/packaging/constraints.txt"
base_stamp="$venv/.workbench-install-$(sha256sum pyproject.toml setup.py "$constraints" | sha256sum | cut -c1-16)"
stamp="$base_stamp${extras:+-test}"
if [ ! -x "$venv/bin/python" ]; then
  "$py" -m venv "$venv"
fi
# a test install (with the [test] extra) also serves the demo
if [ ! -f "$stamp" ] && ! { [ "$mode" = demo ] && [ -f "$base_stamp-test" ]; }; then
  echo "installing the workbench and its dependencies into $venv"
  "$venv/bin/python" -m pip install -q --upgrade pip -c "$constraints"
  "$venv/bin/python" -m pip install -q -e ".$extras" -c "$constraints"
  rm -f "$venv"/.workbench-install-*
  touch "$stamp"
fi

# the project's shared data folder (if present beside the checkout) serves as a
# local mirror of the public sample files, so nothing needs downloading
if [ -d "$root/../shared/data" ]; then
  export WORKBENCH_SAMPLE_MIRRORS="${WORKBENCH_SAMPLE_MIRRORS:-$root/../shared/data}"
fi

# --------------------------------------------------------------- run
export QT_API=pyside6
if [ "$mode" = demo ]; then
  exec "$venv/bin/workbench" demo "$@"
fi

export QT_QPA_PLATFORM="${QT_QPA_PLATFORM:-xcb}"
set +e
"$venv/bin/python" -m pytest -q -p no:cacheprovider --xvfb-backend xvfb "$@"
status=$?
set -e
if [ "$status" = 5 ]; then
  echo "no tests were collected: treating that as a failure" >&2
  exit 1
fi
exit "$status"
