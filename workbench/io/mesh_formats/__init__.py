"""One module per mesh file format, pure Python + numpy (no VTK).

Each module offers ``read(path, data) -> ParsedMesh`` (file units, raises
:class:`~workbench.core.errors.InputError`) and
``encode(vertices, faces, binary=True) -> bytes``.  Use
:mod:`workbench.io.meshes` rather than these modules directly.
"""

from __future__ import annotations
