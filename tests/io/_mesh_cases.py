"""Shared cases for the mesh I/O tests."""

from __future__ import annotations

FORMATS = [
    (".ply", True),
    (".ply", False),
    (".stl", True),
    (".stl", False),
    (".obj", True),
    (".vtk", True),
    (".vtk", False),
    (".vtp", True),
    (".vtp", False),
]
# binary STL stores float32; everything else is written as double
FLOAT32_FORMATS = {(".stl", True)}


def ids(params: list[tuple[str, bool]]) -> list[str]:
    return [f"{ext[1:]}-{'bin' if b else 'txt'}" for ext, b in params]
