#!/usr/bin/env bash
# Build the macOS Workbench.app (one-folder PyInstaller bundle) -- NOT TESTED:
# written on Linux, no Mac was available.  Run on the oldest macOS you support
# (the app runs there and on newer ones), with a python.org or Homebrew
# Python >= 3.11 of the same architecture as the target (arm64 or x86_64;
# PyInstaller does not cross-build).
#
#   bash packaging/macos/build_bundle.sh            # unsigned (ad-hoc) app
#   WORKBENCH_CODESIGN_IDENTITY="Developer ID Application: NAME (TEAMID)" \
#   WORKBENCH_NOTARY_PROFILE=notary bash packaging/macos/build_bundle.sh
#
# Output: build/macos/dist/Workbench.app and build/macos/dist/workbench/.
# See packaging/README.md ("macOS") for the plugins, OpenGL and signing notes.
set -euo pipefail
cd "$(dirname "$0")/../.."
root="$(pwd)"
py="${PYTHON:-python3}"
out="$root/build/macos"
venv="$out/venv"
pyinstaller_version="$(sed -n 's/^pyinstaller==//p' packaging/pyinstaller/requirements.txt)"

rm -rf "$out/dist" "$out/work" "$out/wheel"
mkdir -p "$out"
[ -x "$venv/bin/python" ] || "$py" -m venv "$venv"
"$venv/bin/python" -m pip install -q --upgrade pip
"$venv/bin/python" -m pip install -q -r packaging/pyinstaller/requirements.txt
"$venv/bin/python" -m build --wheel --outdir "$out/wheel" .
"$venv/bin/python" -m pip uninstall -q -y forensic-workbench 2>/dev/null || true
"$venv/bin/python" -m pip install -q "$out"/wheel/*.whl -c packaging/constraints.txt

# the icon: PNGs rendered from the SVG, packed with Apple's iconutil
"$venv/bin/python" packaging/make_icon.py --iconset "$out/workbench.iconset"
iconutil -c icns "$out/workbench.iconset" -o "$out/workbench.icns"

# PyInstaller from outside the checkout, so the installed wheel is what gets bundled
cd "$out"
WORKBENCH_ICON="$out/workbench.icns" "$venv/bin/pyinstaller" --noconfirm --log-level WARN \
  --distpath "$out/dist" --workpath "$out/work" "$root/packaging/pyinstaller/workbench.spec"
app="$out/dist/Workbench.app"

# codesign + notarise when an identity is given (the spec signs every binary
# with it and the hardened-runtime entitlements; here the .app as a whole)
if [ -n "${WORKBENCH_CODESIGN_IDENTITY:-}" ]; then
  codesign --force --deep --options runtime --timestamp \
    --entitlements "$root/packaging/macos/entitlements.plist" \
    --sign "$WORKBENCH_CODESIGN_IDENTITY" "$app"
  codesign --verify --deep --strict --verbose=2 "$app"
  if [ -n "${WORKBENCH_NOTARY_PROFILE:-}" ]; then
    ditto -c -k --keepParent "$app" "$out/Workbench.zip"
    xcrun notarytool submit "$out/Workbench.zip" --keychain-profile "$WORKBENCH_NOTARY_PROFILE" --wait
    xcrun stapler staple "$app"
  fi
fi

# smoke test (pyinstaller $pyinstaller_version): version, the demo, the window
cd /tmp
"$app/Contents/MacOS/workbench" --version
"$app/Contents/MacOS/workbench" demo --out /tmp/workbench-bundle-demo --force --skip-headsq
"$app/Contents/MacOS/workbench" gui --screenshot /tmp/workbench-bundle-window.png
echo "built $app ($(du -sh "$app" | cut -f1)); window picture: /tmp/workbench-bundle-window.png"
