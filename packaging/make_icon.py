"""Render the application icon from its SVG: PNGs, a Windows ``.ico`` and a macOS ``.iconset``.

The icon is drawn by hand in ``workbench/resources/forensic-workbench.svg``; this
script renders it with Qt's SVG renderer (no display needed: the offscreen
platform is used), so the PNG committed beside it can be made again after
an edit::

    python packaging/make_icon.py                        # workbench/resources/forensic-workbench.png (256 px)
    python packaging/make_icon.py --ico build/workbench.ico
    python packaging/make_icon.py --iconset build/workbench.iconset   # then: iconutil -c icns

The ``.ico`` holds 16, 24, 32, 48, 64, 128 and 256 px images (PNG entries,
written here without Qt's ico plugin); the ``.iconset`` folder has the file names
``iconutil`` on macOS expects (``icon_16x16.png`` ... ``icon_512x512@2x.png``).
"""

from __future__ import annotations

import argparse
import os
import struct
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
SVG = ROOT / "workbench" / "resources" / "forensic-workbench.svg"
PNG = ROOT / "workbench" / "resources" / "forensic-workbench.png"
ICO_SIZES = (16, 24, 32, 48, 64, 128, 256)
#: (file name, pixels) of a macOS .iconset
ICONSET = [
    (f"icon_{s}x{s}{suffix}.png", s * scale)
    for s in (16, 32, 128, 256, 512)
    for suffix, scale in (("", 1), ("@2x", 2))
]


def _app():
    os.environ.setdefault("QT_QPA_PLATFORM", "offscreen")
    from PySide6.QtGui import QGuiApplication

    return QGuiApplication.instance() or QGuiApplication(sys.argv[:1])


def render(size: int, svg: Path = SVG):
    """The icon as a ``size`` x ``size`` QImage (transparent corners)."""
    from PySide6.QtCore import Qt
    from PySide6.QtGui import QImage, QPainter
    from PySide6.QtSvg import QSvgRenderer

    _app()
    renderer = QSvgRenderer(str(svg))
    if not renderer.isValid():
        raise SystemExit(f"{svg}: not a valid SVG")
    image = QImage(size, size, QImage.Format.Format_ARGB32)
    image.fill(Qt.GlobalColor.transparent)
    painter = QPainter(image)
    painter.setRenderHint(QPainter.RenderHint.Antialiasing)
    renderer.render(painter)
    painter.end()
    return image


def _save(image, path: Path, fmt: str) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    if not image.save(str(path), fmt):
        raise SystemExit(f"could not write {path} (is Qt's {fmt!r} image plugin there?)")


def write_png(path: Path, size: int = 256) -> None:
    _save(render(size), path, "PNG")


def png_bytes(size: int) -> bytes:
    """The icon rendered at ``size`` px, as PNG file bytes."""
    from PySide6.QtCore import QBuffer, QByteArray, QIODevice

    data = QByteArray()
    buffer = QBuffer(data)
    buffer.open(QIODevice.OpenModeFlag.WriteOnly)
    if not render(size).save(buffer, "PNG"):
        raise SystemExit("Qt could not encode a PNG")
    buffer.close()
    return bytes(data.data())


def write_ico(path: Path, sizes: tuple[int, ...] = ICO_SIZES) -> None:
    """A multi-size Windows .ico: one PNG-compressed image per size.

    Layout (Windows Vista and later read PNG entries at every size): a
    6-byte header (reserved 0, type 1 = icon, image count), one 16-byte
    directory entry per image (width and height with 0 meaning 256, no
    palette, 1 plane, 32 bits per pixel, byte size, file offset), then the
    PNG files one after another.
    """
    images = [png_bytes(s) for s in sizes]
    header = struct.pack("<HHH", 0, 1, len(images))
    offset = len(header) + 16 * len(images)
    entries = b""
    for s, data in zip(sizes, images, strict=True):
        side = 0 if s >= 256 else s
        entries += struct.pack("<BBBBHHII", side, side, 0, 0, 1, 32, len(data), offset)
        offset += len(data)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_bytes(header + entries + b"".join(images))


def write_iconset(folder: Path) -> None:
    folder.mkdir(parents=True, exist_ok=True)
    for name, pixels in ICONSET:
        write_png(folder / name, pixels)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--png", type=Path, default=None, help=f"PNG to write (default {PNG})")
    parser.add_argument("--size", type=int, default=256, help="PNG size in pixels")
    parser.add_argument("--ico", type=Path, help="also write a Windows .ico")
    parser.add_argument("--iconset", type=Path, help="also write a macOS .iconset folder")
    args = parser.parse_args(argv)
    if args.png is not None or (args.ico is None and args.iconset is None):
        write_png(args.png or PNG, args.size)
        print(f"wrote {args.png or PNG}")
    if args.ico is not None:
        write_ico(args.ico)
        print(f"wrote {args.ico}")
    if args.iconset is not None:
        write_iconset(args.iconset)
        print(f"wrote {args.iconset}/ ({len(ICONSET)} PNGs)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
