"""Quick checks of the packaging files (the slow real builds are in packaging/build_*.sh).

* the Linux menu entry parses, starts the ``workbench`` command and names an
  icon that is shipped;
* the PyInstaller spec names every data folder there is, and every file it
  refers to exists;
* ``setup.py``'s build hook copies ``data_tables/`` into the package it
  builds (the ``build_py`` command alone, into a temporary folder);
* the frozen entry point and runtime hook do what the bundle relies on.
"""

from __future__ import annotations

import ast
import configparser
import filecmp
import os
import shutil
import struct
import subprocess
import sys
import tomllib
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]
PACKAGING = REPO / "packaging"
RESOURCES = REPO / "workbench" / "resources"
SPEC = PACKAGING / "pyinstaller" / "workbench.spec"
ENTRY = PACKAGING / "pyinstaller" / "workbench_entry.py"
DESKTOP = PACKAGING / "linux" / "workbench.desktop"


def _desktop_entry() -> configparser.SectionProxy:
    parser = configparser.ConfigParser(interpolation=None)
    parser.optionxform = str  # type: ignore[assignment,method-assign]  # keys are case-sensitive
    parser.read_string(DESKTOP.read_text(encoding="utf-8"))
    return parser["Desktop Entry"]


def _png_size(path: Path) -> tuple[int, int]:
    data = path.read_bytes()[:24]
    assert data[:8] == b"\x89PNG\r\n\x1a\n", f"{path} is not a PNG"
    width, height = struct.unpack(">II", data[16:24])
    return width, height


def test_desktop_entry_starts_workbench_and_names_a_shipped_icon() -> None:
    entry = _desktop_entry()
    assert entry["Type"] == "Application"
    assert entry["Name"]
    scripts = tomllib.loads((REPO / "pyproject.toml").read_text(encoding="utf-8"))["project"][
        "scripts"
    ]
    program, *args = entry["Exec"].split()
    assert program in scripts, f"Exec starts {program!r}, not one of {sorted(scripts)}"
    # a file from the file manager goes to the window, not to the command parser
    assert args[:1] == ["gui"] and args[-1] in {"%f", "%F", "%u", "%U"}
    assert entry["Terminal"] == "false"
    assert entry["Categories"].endswith(";")
    icon = entry["Icon"]
    assert "/" not in icon and not icon.endswith(".png"), "Icon= is a theme name"
    assert _png_size(RESOURCES / f"{icon}.png") == (256, 256)
    svg = ET.parse(RESOURCES / f"{icon}.svg").getroot()
    assert svg.tag.endswith("svg") and svg.get("viewBox") == "0 0 256 256"


def test_desktop_entry_passes_desktop_file_validate() -> None:
    tool = shutil.which("desktop-file-validate")
    if tool is None:
        pytest.skip("desktop-file-validate is not installed (apt-get install desktop-file-utils)")
    done = subprocess.run([tool, str(DESKTOP)], capture_output=True, text=True, check=False)
    assert done.returncode == 0 and not done.stdout.strip(), done.stdout + done.stderr


def test_installing_the_desktop_entry_makes_exec_absolute(tmp_path: Path) -> None:
    program = tmp_path / "bin" / "workbench"
    program.parent.mkdir()
    program.write_text("#!/bin/sh\n", encoding="utf-8")
    program.chmod(0o755)
    share = tmp_path / "share"
    done = subprocess.run(
        ["bash", str(PACKAGING / "linux" / "install_desktop_entry.sh"), "--exec", str(program)]
        + ["--prefix", str(share)],
        capture_output=True,
        text=True,
        check=False,
    )
    assert done.returncode == 0, done.stderr
    installed = (share / "applications" / "forensic-workbench.desktop").read_text(encoding="utf-8")
    assert f'Exec="{program}" gui %f' in installed.splitlines()
    assert (share / "icons/hicolor/256x256/apps/forensic-workbench.png").is_file()
    assert (share / "icons/hicolor/scalable/apps/forensic-workbench.svg").is_file()


def _spec_literal(name: str) -> object:
    tree = ast.parse(SPEC.read_text(encoding="utf-8"))
    for node in tree.body:
        if isinstance(node, ast.Assign) and any(
            isinstance(t, ast.Name) and t.id == name for t in node.targets
        ):
            return ast.literal_eval(node.value)
    raise AssertionError(f"{SPEC.name} has no literal {name}")


def test_spec_requires_data_that_exists_and_covers_every_data_file() -> None:
    required = _spec_literal("REQUIRED_DATA")
    assert isinstance(required, list) and "_data/data_tables" in required
    package = REPO / "workbench"

    def in_checkout(item: str) -> Path:
        # the package's _data/data_tables is the checkout's top-level data_tables/
        return REPO / item.removeprefix("_data/") if item.startswith("_data/") else package / item

    for item in required:
        assert in_checkout(item).exists(), f"{item} ({in_checkout(item)}) does not exist"
    tables = [p for p in (REPO / "data_tables").iterdir() if p.is_dir()]
    assert len(tables) >= 5, "data_tables/ has lost its folders"
    # every non-Python file in the package tree is one the spec requires (so the wheel
    # and the bundle are checked to carry it)
    covered = [in_checkout(item) for item in required]
    data_files = [
        p
        for p in package.rglob("*")
        if p.is_file()
        and p.suffix not in {".py", ".pyc"}
        and "__pycache__" not in p.parts
        and p.name != "py.typed"
    ]
    assert any(p.parent.name == "resources" for p in data_files)
    for path in data_files:
        assert any(path == c or c in path.parents for c in covered), (
            f"{path.relative_to(REPO)} is not covered by REQUIRED_DATA in {SPEC.name}"
        )


def test_spec_refers_to_files_that_exist() -> None:
    text = SPEC.read_text(encoding="utf-8")
    for name in ("workbench_entry.py", "rthook_workbench.py"):
        assert f'"{name}"' in text and (SPEC.parent / name).is_file()
    assert (PACKAGING / "macos" / "entitlements.plist").is_file()
    # the sources the reference head's cache key hashes, shipped beside the modules
    from workbench.services.templates.cache import _SOURCE_GLOBS

    package = REPO / "workbench"
    for pattern in _SOURCE_GLOBS:
        assert list(package.glob(pattern)), f"cache-key glob {pattern!r} matches nothing"


def test_build_py_copies_data_tables_into_the_package(tmp_path: Path) -> None:
    lib = tmp_path / "lib"
    done = subprocess.run(
        [sys.executable, "setup.py", "-q", "egg_info", "--egg-base", str(tmp_path)]
        + ["build_py", "--build-lib", str(lib)],
        cwd=REPO,
        capture_output=True,
        text=True,
        check=False,
    )
    assert done.returncode == 0, done.stdout + done.stderr
    copied = lib / "workbench" / "_data" / "data_tables"
    sources = sorted(p.relative_to(REPO / "data_tables") for p in (REPO / "data_tables").rglob("*"))
    files = [p for p in sources if (REPO / "data_tables" / p).is_file()]
    assert files, "no data tables in the checkout"
    for rel in files:
        target = copied / rel
        assert target.is_file(), f"{rel} not copied"
        assert filecmp.cmp(REPO / "data_tables" / rel, target, shallow=False), f"{rel} differs"
    # package data the wheel needs beside the modules
    assert (lib / "workbench" / "io" / "sample_registry.json").is_file()
    assert (lib / "workbench" / "resources" / "forensic-workbench.png").is_file()
    assert (lib / "workbench" / "core" / "data_paths.py").is_file()


def _entry(*args: str, stdin: str = "") -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, str(ENTRY), *args],
        input=stdin,
        capture_output=True,
        text=True,
        check=False,
        cwd=REPO,
        timeout=120,
    )


def test_frozen_entry_point_is_the_command_line() -> None:
    import workbench

    done = _entry("--version")
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip() == f"workbench {workbench.__version__}"


def test_frozen_entry_point_runs_only_the_helper_process_module() -> None:
    refused = _entry("-m", "os")
    assert refused.returncode == 64 and "not available" in refused.stderr
    # the helper serves requests from stdin until it closes: an empty stdin ends it cleanly
    helper = _entry("-m", "workbench.core.helper_process")
    assert helper.returncode == 0, helper.stderr


def test_runtime_hook_chooses_pyside6_unless_told_otherwise(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    import runpy

    hook = str(PACKAGING / "pyinstaller" / "rthook_workbench.py")
    monkeypatch.delenv("QT_API", raising=False)
    runpy.run_path(hook)
    assert os.environ["QT_API"] == "pyside6"
    monkeypatch.setenv("QT_API", "pyqt5")  # a value already set wins
    runpy.run_path(hook)
    assert os.environ["QT_API"] == "pyqt5"
