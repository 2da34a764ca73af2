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

Images are read with Pillow (PNG, JPEG, TIFF, BMP, ...) and converted to RGB.
"""

from __future__ import annotations

from os import PathLike
from pathlib import Path

import numpy as np

from workbench.core.colour_transfer import ScanColours
from workbench.core.errors import InputError
from workbench.io.mesh_formats import obj, ply
from workbench.io.mesh_formats._common import ParsedMesh

#: texture images larger than this many pixels are refused (memory)
MAX_IMAGE_PIXELS = 16384 * 16384


def read_image(path: str | PathLike[str], role: str = "texture image") -> np.ndarray:
    """An image file as ``(H, W, 3)`` uint8 RGB (first row at the top)."""
    from PIL import Image, UnidentifiedImageError

    path = Path(path)
    if not path.is_file():
        why = "is a folder" if path.is_dir() else "not found"
        raise InputError(path, f"{role} {why}", "check the path and spelling")
    try:
        with Image.open(path) as img:
            if img.width * img.height > MAX_IMAGE_PIXELS:
                raise InputError(
                    path,
                    f"{role} is {img.width} x {img.height} pixels, larger than the "
                    f"{MAX_IMAGE_PIXELS} pixels the workbench reads",
                    "scale it down first",
                )
            rgb = np.asarray(img.convert("RGB"), dtype=np.uint8)
    except InputError:
        raise
    except (UnidentifiedImageError, OSError, ValueError, Image.DecompressionBombError) as exc:
        raise InputError(
            path,
            f"{role} cannot be read ({exc})",
            "use a PNG, JPEG, TIFF or BMP image",
        ) from None
    if rgb.ndim != 3 or 0 in rgb.shape:
        raise InputError(path, f"{role} is empty")
    return np.ascontiguousarray(rgb)


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
    images = [read_image(p, "texture image (map_Kd of the OBJ's material)") for p in files]
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
        image = read_image(texture)
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


__all__ = ["MAX_IMAGE_PIXELS", "read_image", "read_scan_colours"]
