"""Read the colours a scan file carries: vertex colours, or texture coordinates and image.

The colours are aligned with the mesh :func:`workbench.io.meshes.read_mesh`
returns for the same file (it keeps the file's vertices and triangles in
order, removing and merging nothing), so they stay valid after that mesh is
moved into the head frame (x to the subject's left, y up, z toward the face;
mm) or re-wound.  Geometry is not needed here; units do not matter.

* PLY: per-vertex ``red``/``green``/``blue`` (uchar, ushort or float).
* OBJ: ``v x y z r g b`` vertex colours; ``vt`` texture coordinates per face
  corner with the ``map_Kd`` image of the ``mtllib`` material each face uses
  (paths relative to the material file; several texture images are placed
  side by side into one).
* Any format with ``texture=IMAGE``: that image replaces the material's
  (the file must have texture coordinates).

Images are read with Pillow (PNG, JPEG, TIFF, BMP, ...) and kept as uint8 RGB
at a working resolution, within stated limits on their count and pixels
(:func:`read_textures`; the limits in :mod:`workbench.core.limits`).  The fit
works on a repaired, possibly simplified copy of the scan;
:func:`colours_on_working_scan` carries the colours over to it.
"""

from __future__ import annotations

import math
import threading
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from os import PathLike
from pathlib import Path
from typing import Any

import numpy as np

from workbench.core.colour_transfer import ScanColours
from workbench.core.errors import InputError
from workbench.core.limits import (
    SCAN_TEXTURE_MAX_IMAGES,
    SCAN_TEXTURE_MAX_PIXELS,
    SCAN_TEXTURE_MAX_TOTAL_PIXELS,
    SCAN_TEXTURE_WORK_PIXELS,
)
from workbench.core.mesh import Mesh
from workbench.io.mesh_formats import obj, ply
from workbench.io.mesh_formats._common import ParsedMesh

#: texture images larger than this many pixels are refused (memory)
MAX_IMAGE_PIXELS = SCAN_TEXTURE_MAX_PIXELS
#: Pillow's guard is process-wide: one reader at a time changes it
_GUARD = threading.Lock()


@contextmanager
def _opened(path: Path, role: str) -> Iterator[Any]:
    """``PIL.Image.open(path)`` without Pillow's decompression-bomb guard: the callers check
    the header's size against our own stated limit (:data:`MAX_IMAGE_PIXELS`) before
    anything is decoded, and Pillow's default (~179 M pixels) would refuse a
    16384 x 16384 texture the workbench says it takes.  Unreadable files become an :class:`InputError` naming ``path``."""
    from PIL import Image, UnidentifiedImageError

    if not path.is_file():
        why = "is a folder" if path.is_dir() else "not found"
        raise InputError(path, f"{role} {why}", "check the path and spelling")
    with _GUARD:
        before = Image.MAX_IMAGE_PIXELS
        Image.MAX_IMAGE_PIXELS = None  # (the callers check the header's size first)
        try:
            with Image.open(path) as img:
                yield img
        except InputError:
            raise
        except (UnidentifiedImageError, OSError, ValueError, Image.DecompressionBombError) as exc:
            raise InputError(
                path,
                f"{role} cannot be read ({exc})",
                "use a PNG, JPEG, TIFF or BMP image",
            ) from None
        finally:
            Image.MAX_IMAGE_PIXELS = before


def _refuse_too_large(path: Path, role: str, size: tuple[int, int]) -> None:
    width, height = size
    if width * height > MAX_IMAGE_PIXELS:
        raise InputError(
            path,
            f"{role} is {width} x {height} pixels, larger than the {MAX_IMAGE_PIXELS:,} "
            "pixels (16384 x 16384) the workbench reads",
            "scale it down first (the fitted skin's colour atlas is 1024 x 1024 texels)",
        )


def image_size(path: str | PathLike[str], role: str = "texture image") -> tuple[int, int]:
    """``(width, height)`` of an image file from its header (nothing decoded)."""
    path = Path(path)
    with _opened(path, role) as img:
        return int(img.width), int(img.height)


def read_image(
    path: str | PathLike[str], role: str = "texture image", max_pixels: int | None = None
) -> np.ndarray:
    """An image file as ``(H, W, 3)`` uint8 RGB (first row at the top).

    Larger than :data:`MAX_IMAGE_PIXELS` is refused from the header, before
    decoding.  With ``max_pixels`` an image with more pixels is shrunk by the
    smallest whole factor that brings it within (a box filter: each pixel the
    mean of a block; a JPEG is decoded at the reduced scale where it can be).
    """
    from PIL import Image

    path = Path(path)
    with _opened(path, role) as img:
        _refuse_too_large(path, role, img.size)
        factor = 1
        if max_pixels is not None and img.width * img.height > max_pixels:
            factor = math.ceil(math.sqrt(img.width * img.height / max_pixels))
        if factor > 1:
            want = (max(1, img.width // factor), max(1, img.height // factor))
            if img.format == "JPEG":
                img.draft("RGB", want)  # decodes at 1/2, 1/4 or 1/8 scale, no smaller
            rest = max(1, min(img.width // want[0], img.height // want[1]))
            small: Image.Image = img.reduce(rest) if rest > 1 else img
            if small.size != want:
                small = small.resize(want, Image.Resampling.BOX)
            rgb = np.asarray(small.convert("RGB"), dtype=np.uint8)
        else:
            rgb = np.asarray(img.convert("RGB"), dtype=np.uint8)
    if rgb.ndim != 3 or 0 in rgb.shape:
        raise InputError(path, f"{role} is empty")
    return np.ascontiguousarray(rgb)


def read_textures(paths: Sequence[Path], role: str, owner: Path | None = None) -> list[np.ndarray]:
    """The texture images of one scan as uint8 RGB at a working resolution.

    Refused from their headers, before any is decoded: more than
    :data:`~workbench.core.limits.SCAN_TEXTURE_MAX_IMAGES` images, one larger
    than :data:`MAX_IMAGE_PIXELS`, or more than
    :data:`~workbench.core.limits.SCAN_TEXTURE_MAX_TOTAL_PIXELS` together.
    Each is then shrunk by a whole factor so that together they hold at most
    :data:`~workbench.core.limits.SCAN_TEXTURE_WORK_PIXELS` (one decoded at a
    time: the peak memory is one full image, not all of them).  The refusals of
    the set name ``owner`` (the scan whose material lists them), else the first.
    """
    named = owner if owner is not None else paths[0]
    if len(paths) > SCAN_TEXTURE_MAX_IMAGES:
        raise InputError(
            named,
            f"the scan uses {len(paths)} texture images, more than the "
            f"{SCAN_TEXTURE_MAX_IMAGES} the workbench reads for one scan",
            "bake the textures into fewer images (a texture atlas) first",
        )
    sizes = [image_size(p, role) for p in paths]
    for p, size in zip(paths, sizes, strict=True):
        _refuse_too_large(p, role, size)
    total = sum(w * h for w, h in sizes)
    if total > SCAN_TEXTURE_MAX_TOTAL_PIXELS:
        big = " + ".join(f"{w}x{h}" for w, h in sizes[:4]) + (" + ..." if len(sizes) > 4 else "")
        raise InputError(
            named,
            f"the scan's {len(paths)} texture images hold {total / 1e6:,.0f} M pixels "
            f"({big}), more than the {SCAN_TEXTURE_MAX_TOTAL_PIXELS / 1e6:,.0f} M pixels "
            "(32 images of 8192 x 8192) the workbench reads for one scan",
            "scale the textures down first (the fitted skin's colour atlas is "
            "1024 x 1024 texels; 2048 x 2048 per image is plenty)",
        )
    # each its share of the working budget, by its size
    budget = None if total <= SCAN_TEXTURE_WORK_PIXELS else SCAN_TEXTURE_WORK_PIXELS / total
    return [
        read_image(p, role, max_pixels=None if budget is None else max(1, int(w * h * budget)))
        for p, (w, h) in zip(paths, sizes, strict=True)
    ]


def _material_textures(obj_path: Path, libraries: list[str]) -> dict[str, Path]:
    """``map_Kd`` image per material name of the OBJ's material files that exist."""
    textures: dict[str, Path] = {}
    for name in libraries:
        candidates = [name, *name.split()] if " " in name else [name]
        for candidate in candidates:
            mtl = obj_path.parent / candidate
            if not mtl.is_file():
                continue
            current = None
            for raw in mtl.read_text(encoding="utf-8", errors="replace").splitlines():
                line = raw.split("#")[0].strip()
                words = line.split()
                if not words:
                    continue
                if words[0] == "newmtl":
                    current = line[6:].strip()
                elif words[0] in ("map_Kd", "map_kd") and current is not None and len(words) > 1:
                    rest = line[len(words[0]) :].strip()
                    image = mtl.parent / rest
                    if not image.is_file():  # options such as "-s 1 1 1 file.png"
                        image = mtl.parent / words[-1]
                    textures.setdefault(current, image)
            if candidate == name:
                break
    return textures


def _side_by_side(
    images: list[np.ndarray], uv: np.ndarray, which: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """One image holding ``images`` left to right, and ``uv`` mapped into it.

    ``which`` is the image index per triangle (-1: none → NaN coordinates).
    """
    height = max(img.shape[0] for img in images)
    width = sum(img.shape[1] for img in images)
    out = np.zeros((height, width, 3), np.uint8)
    left = 0
    new = np.full_like(uv, np.nan)
    for i, img in enumerate(images):
        h, w = img.shape[:2]
        out[:h, left : left + w] = img
        rows = which == i
        part = np.clip(uv[rows], 0.0, 1.0)
        new[rows, :, 0] = (left + part[..., 0] * w) / width
        new[rows, :, 1] = 1.0 - (1.0 - part[..., 1]) * h / height
        left += w
    return out, new


def _obj_texture(
    path: Path, parsed: ParsedMesh, uv: np.ndarray
) -> tuple[np.ndarray | None, np.ndarray]:
    """The OBJ's own texture image (None when it has none) and the coordinates into it."""
    if parsed.face_material is None or not parsed.material_libraries:
        return None, uv
    textures = _material_textures(path, parsed.material_libraries)
    per_material = [textures.get(name) for name in parsed.material_names]
    files = sorted({p for p in per_material if p is not None}, key=str)
    if not files:
        return None, uv
    images = read_textures(files, "texture image (map_Kd of the OBJ's material)", owner=path)
    lookup = np.array([-1 if p is None else files.index(p) for p in per_material] + [-1])
    which = lookup[parsed.face_material]  # face_material -1 picks the trailing -1
    if len(images) == 1:
        uv = np.where((which >= 0)[:, None, None], uv, np.nan)
        return images[0], uv
    return _side_by_side(images, uv, which)


def read_scan_colours(
    path: str | PathLike[str], texture: str | PathLike[str] | None = None
) -> ScanColours | None:
    """The colours of the scan in ``path``, aligned with ``read_mesh(path).mesh``.

    Parameters
    ----------
    path : path-like
        The scan mesh.  Only ``.ply`` and ``.obj`` carry colours; for the
        other formats the answer is None (and ``texture`` is refused: they
        have no texture coordinates).
    texture : path-like, optional
        A texture image used instead of the OBJ material's ``map_Kd``.

    Returns
    -------
    ScanColours or None
        None when the file carries no colours (and no ``texture`` was given).
        A textured file with vertex colours too keeps both; the texture is used.

    Raises
    ------
    InputError
        Unreadable mesh or image; ``texture`` given for a mesh without
        texture coordinates.
    """
    from workbench.io.meshes import _format_for, _load_bytes

    path = Path(path)
    module = _format_for(path, "read")
    if module not in (ply, obj):
        if texture is not None:
            raise InputError(
                path,
                f"a {path.suffix} mesh has no texture coordinates, so --texture cannot be used",
                "use the scanner's OBJ export (with 'vt' texture coordinates) instead",
            )
        return None
    with np.errstate(all="ignore"):
        parsed = module.read(path, _load_bytes(path))
    n = len(parsed.vertices)
    rgb = parsed.vertex_rgb
    if rgb is not None and len(rgb) != n:
        raise InputError(
            path, f"{len(rgb)} vertex colours for {n} vertices", "export the file again"
        )
    uv, image = parsed.corner_uv, None
    if texture is not None:
        if uv is None:
            why = [m for m in parsed.messages if "texture" in m or "'vt'" in m]
            raise InputError(
                path,
                "--texture was given but the mesh has no texture coordinates"
                + (f" ({why[0]})" if why else ""),
                "export the scan as OBJ with texture coordinates ('vt'), or leave out --texture",
            )
        image = read_textures([Path(texture)], "texture image")[0]
    elif uv is not None and module is obj:
        image, uv = _obj_texture(path, parsed, uv)
    if image is None:
        uv = None
    if rgb is None and image is None:
        return None
    return ScanColours(
        source=str(path),
        n_vertices=n,
        faces=parsed.faces,
        vertex_rgb=rgb,
        corner_uv=uv,
        image=image,
    )


def colours_on_working_scan(
    colours: ScanColours,
    file_vertices: np.ndarray,
    working: Mesh,
    vertex_of: np.ndarray | None,
    face_source: np.ndarray | None,
) -> ScanColours:
    """``colours`` (aligned with the file's mesh) aligned with ``working``, the scan the
    fit uses (:func:`workbench.services.scan_fit.checks.prepare_scan`).

    With ``vertex_of`` (each file vertex's working vertex, -1: left out) and
    ``face_source`` (each working triangle's file triangle), vertex colours
    follow their vertices (a welded vertex takes one of its copies' colours)
    and texture coordinates their triangles.  A simplified scan (both None) has
    new vertices: each takes the colour of the file vertex nearest to it (its
    vertex colour, or the texture at one of its corners' coordinates), as
    vertex colours.
    """
    if vertex_of is not None and face_source is not None:
        n = working.n_vertices
        rgb = None
        if colours.vertex_rgb is not None:
            source = np.zeros(n, np.int64)
            kept = np.flatnonzero(vertex_of >= 0)
            source[vertex_of[kept]] = kept
            rgb = colours.vertex_rgb[source]
        uv = faces = None
        if colours.corner_uv is not None:
            uv = colours.corner_uv[face_source]
            faces = vertex_of[colours.faces[face_source]]  # the file's corner order
        return ScanColours(
            source=colours.source,
            n_vertices=n,
            faces=working.faces if faces is None else faces,
            vertex_rgb=rgb,
            corner_uv=uv,
            image=None if uv is None else colours.image,
        )
    from scipy.spatial import cKDTree

    from workbench.core.colour_transfer import sample_image

    used = np.unique(colours.faces)
    _, j = cKDTree(file_vertices[used]).query(working.vertices, workers=-1)
    nearest = used[j]
    if colours.image is not None and colours.corner_uv is not None:
        corner = np.full(colours.n_vertices, -1, np.int64)
        corner[colours.faces.ravel()[::-1]] = np.arange(colours.faces.size)[::-1]
        uv = colours.corner_uv.reshape(-1, 2)[corner[nearest]]
        sampled = sample_image(colours.image, uv)
        rgb = np.clip(np.rint(np.nan_to_num(sampled, nan=128.0)), 0, 255).astype(np.uint8)
    else:
        assert colours.vertex_rgb is not None
        rgb = colours.vertex_rgb[nearest]
    return ScanColours(
        source=colours.source, n_vertices=working.n_vertices, faces=working.faces, vertex_rgb=rgb
    )


__all__ = [
    "MAX_IMAGE_PIXELS",
    "colours_on_working_scan",
    "image_size",
    "read_image",
    "read_scan_colours",
    "read_textures",
]
