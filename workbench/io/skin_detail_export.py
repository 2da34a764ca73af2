"""Write and read a fitted skin's detail layer (:mod:`workbench.core.detail_layer`).

Two files in a scan-fit pack:

``skin_detailed.ply``
    The detailed skin itself (the Loop-subdivided fitted skin with the scan's
    fine detail), for tools that only want a mesh.
``skin_detail.npz``
    The layer: ``levels`` (Loop steps), ``displacement`` (mm along each fine
    vertex's unit normal, outward positive), ``observed`` (the fine vertex
    found the scan) and ``coarse_faces`` (the control topology it belongs to).
    :func:`read_skin_detail` rebuilds the layer over any skin of that
    topology, so an animated, aged or warped fitted skin can be re-detailed:
    ``read_skin_detail(path, skin).apply(skin.vertices)``.

Frame and units: the head frame of the pack (x to the subject's left, x = 0
midsagittal, y up, z toward the face), mm.  Arrays are stored without pickles.
"""

from __future__ import annotations

import io
from os import PathLike
from pathlib import Path

import numpy as np

from workbench.core.detail_layer import DetailLayer, subdivision_of
from workbench.core.errors import InputError
from workbench.core.mesh import Mesh
from workbench.io.mesh_formats import ply
from workbench.io.skin_colour_export import HEAD_FRAME_COMMENT

PLY_NAME = "skin_detailed.ply"
NPZ_NAME = "skin_detail.npz"


def write_skin_detail(folder: str | PathLike[str], detail: DetailLayer, skin: Mesh) -> list[Path]:
    """``skin_detailed.ply`` and ``skin_detail.npz`` for ``detail`` over the fitted ``skin``
    (head frame, mm) into ``folder`` (a staged pack: the caller makes the whole atomic)."""
    folder = Path(folder)
    detailed = detail.apply(skin.vertices)
    ply_path = folder / PLY_NAME
    ply_path.write_bytes(
        ply.encode(
            detailed.vertices,
            np.asarray(detailed.faces),
            binary=True,
            comments=[
                HEAD_FRAME_COMMENT,
                f"detail: skin.ply after {detail.levels} Loop steps, displaced onto the scan "
                f"({int(detail.observed.sum())} of {detailed.n_vertices} vertices observed)",
            ],
        )
    )
    buf = io.BytesIO()
    np.savez_compressed(
        buf,
        levels=np.int64(detail.levels),
        displacement=detail.displacement.astype(np.float32),
        observed=detail.observed.astype(bool),
        coarse_faces=np.asarray(skin.faces, np.int32),
    )
    npz_path = folder / NPZ_NAME
    npz_path.write_bytes(buf.getvalue())
    return [ply_path, npz_path]


def read_skin_detail(path: str | PathLike[str], skin: Mesh) -> DetailLayer:
    """The detail layer stored at ``path``, over ``skin`` (which must have the topology
    the layer was built on; its vertices may have moved)."""
    path = Path(path)
    try:
        with np.load(path, allow_pickle=False) as z:
            levels = int(z["levels"])
            displacement = np.asarray(z["displacement"], np.float64)
            observed = np.asarray(z["observed"], bool)
            coarse_faces = np.asarray(z["coarse_faces"], np.int64)
    except FileNotFoundError:
        raise InputError(path, "file not found") from None
    except (OSError, ValueError, KeyError) as exc:
        raise InputError(
            path, f"not a skin detail file ({exc})", "use the skin_detail.npz of a scan-fit pack"
        ) from None
    if coarse_faces.shape != np.asarray(skin.faces).shape or not np.array_equal(
        coarse_faces, skin.faces
    ):
        raise InputError(
            path,
            f"belongs to a skin of {len(coarse_faces)} triangles with other connectivity than "
            f"this one ({skin.n_faces} triangles)",
            "use the skin of the pack it came with",
        )
    if not 0 <= levels <= 4:
        raise InputError(path, f"absurd number of subdivision levels: {levels}")
    matrix, faces = subdivision_of(skin, levels)
    if len(displacement) != matrix.shape[0] or len(observed) != matrix.shape[0]:
        raise InputError(
            path,
            f"{len(displacement)} displacements for {matrix.shape[0]} fine vertices",
            "the file is damaged",
        )
    if not np.isfinite(displacement).all():
        raise InputError(path, "displacements that are not finite numbers", "the file is damaged")
    return DetailLayer(levels, matrix, faces, displacement, observed)
