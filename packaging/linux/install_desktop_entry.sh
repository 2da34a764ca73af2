#!/usr/bin/env bash
# Install the workbench's menu entry and icon for the current user (or --prefix).
#
#   bash install_desktop_entry.sh [--exec PROGRAM] [--prefix DIR] [--uninstall]
#
# PROGRAM is the workbench executable the menu entry starts: by default the
# bundle's ``workbench`` when this script sits in a bundle folder
# (dist/workbench/), else ``workbench`` found on PATH (a pip install).  DIR is
# the XDG data folder (default ${XDG_DATA_HOME:-~/.local/share}; /usr/local/share
# for all users, as root).  Files written:
#   DIR/applications/forensic-workbench.desktop        (Exec= made absolute)
#   DIR/icons/hicolor/256x256/apps/forensic-workbench.png
#   DIR/icons/hicolor/scalable/apps/forensic-workbench.svg
set -euo pipefail

here="$(cd "$(dirname "$0")" && pwd)"
prefix="${XDG_DATA_HOME:-$HOME/.local/share}"
program=""
uninstall=0
while [ $# -gt 0 ]; do
  case "$1" in
    --exec) program="$2"; shift 2 ;;
    --prefix) prefix="$2"; shift 2 ;;
    --uninstall) uninstall=1; shift ;;
    -h|--help) sed -n '2,14p' "$0"; exit 0 ;;
    *) echo "unknown option: $1 (see --help)" >&2; exit 64 ;;
  esac
done

apps="$prefix/applications"
icons="$prefix/icons/hicolor"
if [ "$uninstall" = 1 ]; then
  rm -f "$apps/forensic-workbench.desktop" "$icons/256x256/apps/forensic-workbench.png" \
    "$icons/scalable/apps/forensic-workbench.svg"
  echo "removed the workbench menu entry and icon from $prefix"
  exit 0
fi

# the executable: given, the bundle's beside this script, or the one on PATH
if [ -z "$program" ]; then
  if [ -x "$here/workbench" ]; then
    program="$here/workbench"
  elif command -v workbench >/dev/null 2>&1; then
    program="$(command -v workbench)"
  else
    echo "no workbench executable found: pass --exec PROGRAM" >&2
    exit 1
  fi
fi
program="$(cd "$(dirname "$program")" && pwd)/$(basename "$program")"

# the icon: in a bundle (_internal/workbench/resources), a checkout
# (workbench/resources), or the installed package of the program's venv
icon_dir=""
for d in "$here/_internal/workbench/resources" "$here/../../workbench/resources"; do
  if [ -f "$d/forensic-workbench.png" ]; then icon_dir="$d"; break; fi
done
if [ -z "$icon_dir" ] && [ -x "$(dirname "$program")/python" ]; then
  icon_dir="$("$(dirname "$program")/python" -c \
    'import pathlib, workbench; print(pathlib.Path(workbench.__file__).parent / "resources")')"
fi
if [ ! -f "$icon_dir/forensic-workbench.png" ]; then
  echo "icon forensic-workbench.png not found (looked beside this script and in the package)" >&2
  exit 1
fi
desktop="$here/workbench.desktop"
[ -f "$desktop" ] || desktop="$here/linux/workbench.desktop"

mkdir -p "$apps" "$icons/256x256/apps" "$icons/scalable/apps"
install -m 644 "$icon_dir/forensic-workbench.png" "$icons/256x256/apps/forensic-workbench.png"
if [ -f "$icon_dir/forensic-workbench.svg" ]; then
  install -m 644 "$icon_dir/forensic-workbench.svg" "$icons/scalable/apps/forensic-workbench.svg"
fi
quoted="\"$program\""
sed -e "s|^Exec=workbench |Exec=$quoted |" -e "s|^TryExec=workbench\$|TryExec=$program|" \
  "$desktop" > "$apps/forensic-workbench.desktop"
chmod 644 "$apps/forensic-workbench.desktop"
command -v update-desktop-database >/dev/null 2>&1 && update-desktop-database -q "$apps" || true
command -v gtk-update-icon-cache >/dev/null 2>&1 && gtk-update-icon-cache -q -t "$icons" || true
echo "installed $apps/forensic-workbench.desktop (runs $program) and its icon under $icons"
