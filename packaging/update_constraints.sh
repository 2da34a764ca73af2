#!/usr/bin/env bash
# Move packaging/constraints.txt to the newest releases the test suite passes with.
#
#   bash packaging/update_constraints.sh
#
# Builds a throw-away virtual environment, installs the workbench with its
# test tools *without* the constraints (so pip picks the newest releases
# allowed by pyproject.toml), runs the whole suite there twice (the second
# run with the caches the first one filled) and, only if both pass, writes
# the environment's versions to packaging/constraints.txt.  Review the diff
# and commit it on its own.
set -euo pipefail
cd "$(dirname "$0")/.."
root="$(pwd)"
py="${PYTHON:-python3}"
tmp="$(mktemp -d)"
trap 'rm -rf "$tmp"' EXIT
"$py" -m venv "$tmp/venv"
"$tmp/venv/bin/python" -m pip install -q --upgrade pip
"$tmp/venv/bin/python" -m pip install -q -e ".[test]"
export QT_API=pyside6 QT_QPA_PLATFORM="${QT_QPA_PLATFORM:-xcb}"
if [ -d "$root/../shared/data" ]; then
  export WORKBENCH_SAMPLE_MIRRORS="${WORKBENCH_SAMPLE_MIRRORS:-$root/../shared/data}"
fi
export XDG_CACHE_HOME="$tmp/cache"
for run in cold warm; do
  echo "test suite ($run cache) with the newest releases"
  "$tmp/venv/bin/python" -m pytest -q -p no:cacheprovider --xvfb-backend xvfb
done
{
  echo "# Versions the test suite passes with (CI: fresh Debian machine, Python 3.11, 2 cores)."
  echo "# Used by both README commands (packaging/bootstrap.sh installs with -c this file)."
  echo "# Update: bash packaging/update_constraints.sh (fresh venv, newest releases, whole suite, then rewrite)."
  "$tmp/venv/bin/python" -m pip freeze --all --exclude-editable | grep -v -i -E '^(setuptools|wheel)=='
} > packaging/constraints.txt.new
mv packaging/constraints.txt.new packaging/constraints.txt
echo "packaging/constraints.txt updated; review with: git diff packaging/constraints.txt"
