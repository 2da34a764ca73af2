"""Mesh files that are broken, and writes that fail: clear errors, nothing lost."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest
from _mesh_cases import FORMATS
from _mesh_cases import ids as _ids

from workbench.core.errors import InputError
from workbench.core.mesh import Mesh
from workbench.io import atomic
from workbench.io.mesh_formats import ply as ply_format
from workbench.io.meshes import SUPPORTED_EXTENSIONS, read_mesh, write_mesh

# ------------------------------------------------------------------ errors
# OBJ has no length information: a cut between face lines cannot be detected, so
# OBJ is only cut inside the vertex block (which leaves no faces)
CUTS = [
    (ext, binary, keep)
    for ext, binary in FORMATS
    for keep in (0.5, 0.95)
    if not (ext == ".obj" and keep > 0.5)
]


CUT_IDS = [
    f"{name}-{keep}" for name, (_, _, keep) in zip(_ids([c[:2] for c in CUTS]), CUTS, strict=False)
]


@pytest.mark.parametrize(("ext", "binary", "keep"), CUTS, ids=CUT_IDS)
def test_truncated_files_raise_input_error(tmp_path, head_mesh, ext, binary, keep):
    path = write_mesh(tmp_path / f"cut{ext}", head_mesh, binary=binary)
    data = path.read_bytes()
    path.write_bytes(data[: int(len(data) * keep)])
    with pytest.raises(InputError) as info:
        read_mesh(path)
    assert str(path) in str(info.value)


@pytest.mark.parametrize(
    ("name", "content", "words"),
    [
        (
            "junk.ply",
            b"ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nend_header\n1\n2\n3\n",
            "x, y and z",
        ),
        (
            "range.ply",
            b"ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n"
            b"property float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n"
            b"0 0 0\n1 0 0\n0 1 0\n3 0 1 7\n",
            "out of range",
        ),
        (
            "text.ply",
            b"ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\n"
            b"property float z\nend_header\n0 zero 0\n",
            "non-numeric",
        ),
        ("points.obj", b"v 0 0 0\nv 1 0 0\nv 0 1 0\n", "no triangles"),
        ("text.obj", b"v 0 0 0\nv 1 zero 0\nv 0 1 0\nf 1 2 3\n", "non-numeric"),
        ("zero.obj", b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 0 1 2\n", "index 0"),
        ("range.obj", b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 4\n", "out of range"),
        (
            "grid.vtk",
            b"# vtk DataFile Version 3.0\nt\nASCII\nDATASET STRUCTURED_POINTS\n",
            "POLYDATA",
        ),
        ("notxml.vtp", b"<VTKFile type='PolyData'><PolyData>", "malformed"),
        ("grid.vtp", b"<VTKFile type='ImageData'/>", "PolyData"),
        ("short.stl", b"not an stl", "truncated"),
        ("empty.ply", b"", "empty"),
    ],
)
def test_bad_files_raise_plain_input_error(tmp_path, name, content, words):
    path = tmp_path / name
    path.write_bytes(content)
    with pytest.raises(InputError) as info:
        read_mesh(path)
    assert str(path) in str(info.value)
    assert words in str(info.value)


def test_missing_file_and_unknown_extension(tmp_path):
    with pytest.raises(InputError, match="not found"):
        read_mesh(tmp_path / "nope.ply")
    odd = tmp_path / "mesh.off"
    odd.write_text("OFF\n")
    with pytest.raises(InputError) as info:
        read_mesh(odd)
    for ext in SUPPORTED_EXTENSIONS:
        assert ext in str(info.value)
    with pytest.raises(InputError, match="supported extensions"):
        write_mesh(tmp_path / "mesh.off", Mesh(np.eye(3), [[0, 1, 2]]))


def test_bad_units_arguments(skull_obj):
    with pytest.raises(InputError, match="unknown unit"):
        read_mesh(skull_obj, units="furlong")
    with pytest.raises(InputError, match="not both"):
        read_mesh(skull_obj, units="cm", scale=10)
    with pytest.raises(InputError, match="positive"):
        read_mesh(skull_obj, scale=-1)


# ------------------------------------------------------------------ atomic writes
def _folder_state(folder: Path) -> dict[str, bytes]:
    return {p.name: p.read_bytes() for p in folder.iterdir()}


def test_write_is_atomic_when_encoding_fails(tmp_path, head_mesh, monkeypatch):
    target = write_mesh(tmp_path / "head.ply", head_mesh)
    before = _folder_state(tmp_path)

    def broken(*args, **kwargs):
        raise RuntimeError("encoder exploded")

    monkeypatch.setattr(ply_format, "encode", broken)
    with pytest.raises(RuntimeError):
        write_mesh(target, Mesh(head_mesh.vertices * 2, head_mesh.faces))
    assert _folder_state(tmp_path) == before


def test_write_is_atomic_when_replace_fails(tmp_path, head_mesh, monkeypatch):
    target = write_mesh(tmp_path / "head.vtp", head_mesh)
    before = _folder_state(tmp_path)

    def refuse(src, dst):
        raise PermissionError(13, "Permission denied")

    monkeypatch.setattr(atomic.os, "replace", refuse)
    with pytest.raises(InputError, match="cannot be written"):
        write_mesh(target, Mesh(head_mesh.vertices * 2, head_mesh.faces))
    monkeypatch.undo()
    assert _folder_state(tmp_path) == before
    assert read_mesh(target).mesh.equals(head_mesh)
    assert os.listdir(tmp_path) == ["head.vtp"]


@pytest.mark.parametrize(("ext", "binary"), FORMATS, ids=_ids(FORMATS))
def test_damaged_bytes_give_input_error_not_tracebacks(tmp_path, head_mesh, ext, binary):
    """Random byte damage either still parses or raises InputError, nothing else."""
    data = write_mesh(tmp_path / f"good{ext}", head_mesh, binary=binary).read_bytes()
    rng = np.random.default_rng(20240611)
    path = tmp_path / f"damaged{ext}"
    for _ in range(40):
        buf = bytearray(data)
        region = len(buf) if rng.random() < 0.5 else min(300, len(buf))
        for _ in range(int(rng.integers(1, 12))):
            buf[int(rng.integers(region))] = int(rng.integers(256))
        path.write_bytes(bytes(buf))
        try:
            read_mesh(path)
        except InputError as error:
            assert str(path) in str(error)
