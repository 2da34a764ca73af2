"""A4 PDF building blocks for reports (fpdf2; pure Python, no rendering).

Page furniture (footer with case id and "page n of N"), headings, key-value
blocks, tables, warning boxes and rows of captioned pictures, which
:mod:`workbench.reporting.report` arranges into the reconstruction report
(see ``reports/README.md``).  Numbers arrive in mm; pictures as PNG *paths*.

Text is set in DejaVu Sans / Sans Mono when the TTF files are found (system
font folders, ``WORKBENCH_REPORT_FONT_DIR``, or matplotlib's copy), so names
such as "Kähler", "±" and "–" print as they are; otherwise the PDF core fonts
are used and text outside Latin-1 is transliterated ("–" → "-").
"""

from __future__ import annotations

import importlib.util
import os
import unicodedata
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from fpdf import FPDF, FontFace
from fpdf.util import Padding
from PIL import Image

FONT_DIRS = (
    "/usr/share/fonts/truetype/dejavu",
    "/usr/share/fonts/TTF",
    "/usr/share/fonts/dejavu",
    "/usr/share/fonts/dejavu-sans-fonts",
    "/usr/local/share/fonts",
    "/Library/Fonts",
    "C:/Windows/Fonts",
)
_FACES = {"": "DejaVuSans.ttf", "B": "DejaVuSans-Bold.ttf", "I": "DejaVuSans-Oblique.ttf"}
_MONO = "DejaVuSansMono.ttf"
_ASCII = {
    "–": "-",
    "—": "-",
    "−": "-",
    "‘": "'",
    "’": "'",
    "“": '"',
    "”": '"',
    "…": "...",
    "≤": "<=",
    "≥": ">=",
    "→": "->",
    "·": "-",
    "≈": "~",
    "×": "x",
    "•": "-",
}
VIEWS = ("front", "side", "three_quarter")
#: picture groups: (key prefix, heading)
GROUPS = (
    ("skull_dowels_", "Skull with tissue-depth dowels"),
    ("face_skull_", "Reconstructed face over the skull"),
    ("face_", "Reconstructed face"),
)
GREY, DARK, ACCENT = (110, 110, 110), (30, 30, 30), (35, 70, 120)


def find_fonts() -> dict[str, Path] | None:
    """DejaVu TTF files ``{"": regular, "B": bold, "I": oblique, "mono": mono}`` or None."""
    dirs = [os.environ.get("WORKBENCH_REPORT_FONT_DIR", ""), *FONT_DIRS]
    spec = importlib.util.find_spec("matplotlib")
    if spec and spec.origin:
        dirs.append(str(Path(spec.origin).parent / "mpl-data" / "fonts" / "ttf"))
    for folder in filter(None, dirs):
        base = Path(folder)
        if (base / _FACES[""]).is_file() and (base / _MONO).is_file():
            found = {k: base / v for k, v in _FACES.items() if (base / v).is_file()}
            return {**found, "mono": base / _MONO}
    return None


def transliterate(text: str) -> str:
    """Latin-1 text for the PDF core fonts ("–" → "-", "ł" → "l", else "?")."""
    out = []
    for ch in text:
        ch = _ASCII.get(ch, ch)
        if all(ord(c) < 256 for c in ch):
            out.append(ch)
            continue
        base = unicodedata.normalize("NFKD", ch).encode("latin-1", "ignore").decode("latin-1")
        out.append(base or "?")
    return "".join(out)


def num(value: Any, digits: int = 1) -> str:
    """A number for a table cell; ``None`` prints as an en dash."""
    if value is None:
        return "–"
    if isinstance(value, bool):
        return "yes" if value else "no"
    if isinstance(value, int):
        return str(value)
    if isinstance(value, float):
        return f"{value:.{digits}f}"
    return str(value)


#: short lowercase words a note may start with that are words, not landmark codes
_WORDS = frozenset(
    {"a", "an", "all", "at", "in", "it", "its", "no", "not", "on", "one", "set", "two"}
)


def sentence(text: Any) -> str:
    """A note as a sentence: its first word capitalised (not when it is a code such as
    ``pg`` or ``iC_r``) and a full stop at the end; the words themselves are kept."""
    text = str(text).strip()
    if not text:
        return text
    first = text.split(" ", 1)[0].rstrip(":,;")
    if first.isalpha() and first.islower() and (len(first) > 3 or first in _WORDS):
        text = text[0].upper() + text[1:]
    return text if text.endswith((".", "!", "?")) else text + "."


def describe_value(value: Any) -> str:
    """A guide value in words: number (mm), point, line or mapping."""
    if isinstance(value, list) and value and all(isinstance(v, int | float) for v in value):
        return "(" + ", ".join(f"{v:.1f}" for v in value) + ")"
    if isinstance(value, list) and value and all(isinstance(v, list) for v in value):
        return " – ".join(describe_value(v) for v in value)
    if isinstance(value, dict):
        return "; ".join(f"{k} {describe_value(v)}" for k, v in value.items())
    if isinstance(value, int | float) and not isinstance(value, bool):
        return f"{value:.1f} mm"
    return num(value)


class ReportPDF(FPDF):
    """FPDF with the report's fonts, footer and a few layout helpers."""

    def __init__(self, case_id: str, created: str, software: str) -> None:
        super().__init__(orientation="P", unit="mm", format="A4")
        self.case_id, self.created, self.software = case_id, created, software
        self.set_margins(15, 15, 15)
        self.set_auto_page_break(True, margin=18)
        self.set_title(f"Reconstruction report, case {case_id}")
        self.set_creator(software)
        fonts = find_fonts()
        self.unicode = fonts is not None
        if fonts:
            for style, path in fonts.items():
                if style != "mono":
                    self.add_font("DejaVu", style, str(path))
            self.add_font("DejaVuMono", "", str(fonts["mono"]))
            self.sans, self.mono, self.styles = (
                "DejaVu",
                "DejaVuMono",
                {s for s in fonts if s != "mono"},
            )
        else:
            self.sans, self.mono, self.styles = "helvetica", "courier", {"", "B", "I"}

    # ---------------------------------------------------------------- text
    def t(self, text: Any) -> str:
        text = "" if text is None else str(text)
        return text if self.unicode else transliterate(text)

    def font(self, size: float, style: str = "", mono: bool = False) -> None:
        style = style if style in self.styles else ""
        self.set_font(self.mono if mono else self.sans, style, size)

    def face(
        self,
        style: str = "",
        *,
        mono: bool = False,
        size: float | None = None,
        color: Sequence[int] | None = None,
    ) -> FontFace:
        return FontFace(
            family=self.mono if mono else self.sans,
            emphasis=style if style in self.styles and style else None,
            size_pt=size,
            color=color,
        )

    def footer(self) -> None:
        self.set_y(-13)
        self.font(7.5)
        self.set_text_color(*GREY)
        self.set_draw_color(200, 200, 200)
        self.line(self.l_margin, self.get_y(), self.w - self.r_margin, self.get_y())
        width = (self.w - self.l_margin - self.r_margin) / 2
        self.cell(width, 6, self.t(f"Case {self.case_id} · {self.software} · {self.created}"))
        self.cell(width, 6, f"page {self.page_no()} of {{nb}}", align="R")
        self.set_text_color(*DARK)

    def heading(self, text: str, min_space: float = 30.0) -> None:
        if self.get_y() + min_space > self.page_break_trigger:
            self.add_page()
        self.ln(3)
        self.font(12, "B")
        self.set_text_color(*ACCENT)
        self.cell(0, 7, self.t(text), new_x="LMARGIN", new_y="NEXT")
        self.set_draw_color(*ACCENT)
        self.line(self.l_margin, self.get_y(), self.w - self.r_margin, self.get_y())
        self.ln(2)
        self.set_text_color(*DARK)

    def subheading(self, text: str) -> None:
        self.font(9.5, "B")
        self.cell(0, 6, self.t(text), new_x="LMARGIN", new_y="NEXT")

    def para(
        self, text: str, size: float = 9, style: str = "", color: Sequence[int] = DARK
    ) -> None:
        self.font(size, style)
        self.set_text_color(*color)
        self.multi_cell(0, size * 0.45, self.t(text), new_x="LMARGIN", new_y="NEXT", align="L")
        self.set_text_color(*DARK)

    def box(self, title: str, lines: Sequence[str], fill: Sequence[int] = (255, 243, 205)) -> None:
        self.set_fill_color(*fill)
        self.font(9, "B")
        self.multi_cell(
            0,
            5,
            self.t(title),
            fill=True,
            new_x="LMARGIN",
            new_y="NEXT",
            align="L",
            padding=Padding(1.5, 2, 0, 2),
        )
        self.font(8.5)
        self.multi_cell(
            0,
            4.2,
            self.t("\n".join(f"• {line}" for line in lines)),
            fill=True,
            new_x="LMARGIN",
            new_y="NEXT",
            align="L",
            padding=Padding(0.5, 2, 1.5, 2),
        )
        self.set_fill_color(255, 255, 255)
        self.ln(1)

    def numbered(self, items: Sequence[str], start: int = 1, size: float = 8.5) -> int:
        """``items`` as a numbered list of sentences (:func:`sentence`), each with a hanging
        indent; returns the number after the last item."""
        indent = 8.0
        for n, item in enumerate(items, start):
            self.font(size)
            self.set_text_color(*DARK)
            if self.get_y() + 2 * size * 0.45 > self.page_break_trigger:
                self.add_page()
            self.set_x(self.l_margin)
            self.cell(indent, size * 0.45, f"{n}.", align="R")
            self.set_x(self.l_margin + indent + 1.5)
            self.multi_cell(
                0, size * 0.45, self.t(sentence(item)), new_x="LMARGIN", new_y="NEXT", align="L"
            )
            self.ln(0.8)
        return start + len(items)

    def notes_pointer(self, count: int, link: int | None = None, about: str = "") -> None:
        """One grey line saying how many technical notes the closing appendix holds (a
        link to it with ``link``); nothing when there are none."""
        if not count:
            return
        self.ln(1)
        self.font(8)
        self.set_text_color(*GREY)
        self.multi_cell(
            0,
            4,
            self.t(
                f"{count} technical note{'s' if count != 1 else ''}{about}: see "
                "'Appendix: technical notes' at the end of this report."
            ),
            new_x="LMARGIN",
            new_y="NEXT",
            link=link,
        )
        self.set_text_color(*DARK)

    def notes_appendix(
        self,
        groups: Sequence[tuple[str, Sequence[str]]],
        intro: str,
        link: int | None = None,
        title: str = "Appendix: technical notes",
    ) -> None:
        """The closing section of a report: every note, in full, as numbered sentences under
        the subheading of its group (a group without a title: no subheading).  ``link``
        (from :meth:`add_link`) is pointed at the section's heading."""
        self.heading(title, min_space=40)
        if link is not None:
            self.set_link(link, y=max(self.get_y() - 12, 0), page=self.page_no())
        self.para(intro, size=8, color=GREY)
        self.ln(1)
        n = 1
        for name, items in groups:
            if not items:
                continue
            if name:
                if self.get_y() + 16 > self.page_break_trigger:
                    self.add_page()
                self.ln(1)
                self.subheading(name)
            n = self.numbered(items, n)

    def grid(
        self,
        headers: Sequence[str],
        rows: Sequence[Sequence[Any]],
        widths: Sequence[float],
        *,
        aligns: Sequence[str] | None = None,
        styles: Sequence[FontFace | None] | None = None,
        size: float = 8,
        col_styles: dict[int, FontFace] | None = None,
    ) -> None:
        """A table with a heading row; ``styles`` per row, ``col_styles`` per column.

        Drawn here cell by cell (word wrap from the font's widths, one ``cell`` per
        line) rather than with fpdf's ``table``, whose layout of a report's ~1,800
        cells took 1.2 s of a 20 s job.  Every other data row is shaded; the heading
        row is bold on blue-grey, ruled below, and repeated at the top of each page
        the table continues on.
        """
        aligns = list(aligns or ["L"] * len(widths))
        base = FontFace(family=self.sans, emphasis=None, size_pt=size)
        head_face = FontFace(
            family=self.sans,
            emphasis="B" if "B" in self.styles else None,
            size_pt=size,
            fill_color=(232, 238, 246),
        )
        lines_h = size * 0.5
        pad = (0.8, 1.2, 0.8, 1.2)  # top, right, bottom, left (mm)
        x0 = self.l_margin

        def use(face: FontFace | None) -> None:
            face = face or base
            family = face.family or self.sans
            style = face.emphasis.style if face.emphasis is not None else ""
            if family == self.sans:  # only the faces found (bold may be missing)
                style = "".join(ch for ch in style if ch in self.styles)
            self.set_font(family, style, face.size_pt or size)
            self.set_text_color(face.color if face.color is not None else DARK)

        def layout(values: Sequence[Any], faces: Sequence[FontFace | None]) -> list[list[str]]:
            out = []
            for value, width, face in zip(values, widths, faces, strict=True):
                use(face)
                out.append(self._wrap(self.t(value), width - pad[1] - pad[3]))
            return out

        heads = [head_face] * len(widths)
        rule_y: float | None = None  # the rule under the heading row, drawn again below

        def draw(values: Sequence[Any], faces: Sequence[FontFace | None], fill=None) -> None:
            nonlocal rule_y
            heading = faces is heads
            cells = layout(values, faces)
            height = max(len(c) for c in cells) * lines_h + pad[0] + pad[2]
            if not heading and self.get_y() + height > self.page_break_trigger:
                self.add_page(orientation=str(self.cur_orientation.value))
                if headers:
                    draw(headers, heads)
            y = self.get_y()
            x = x0
            for lines, width, face, align in zip(cells, widths, faces, aligns, strict=True):
                colour = (face.fill_color if face is not None else None) or fill
                if colour is not None:
                    self.set_fill_color(colour)
                    self.rect(x, y, width, height, style="F")
                use(face)
                for k, line in enumerate(lines):
                    self.set_xy(x + pad[3], y + pad[0] + k * lines_h)
                    self.cell(width - pad[1] - pad[3], lines_h, line, align=align)
                x += width
            self.set_xy(x0, y + height)
            self.set_fill_color(255, 255, 255)  # each row sets its own shading again
            if heading:
                rule_y = y + height
            if rule_y is not None:  # again after the row below, whose shading covers it
                self.set_draw_color(*DARK)
                self.set_line_width(0.2)
                self.line(x0, rule_y, x0 + sum(widths), rule_y)
                if not heading:
                    rule_y = None

        self.set_x(x0)
        if headers:
            # the heading row is not left alone at the foot of a page
            first = layout(headers, heads)
            need = 2 * (max(len(c) for c in first) * lines_h + pad[0] + pad[2])
            if self.get_y() + need > self.page_break_trigger:
                self.add_page(orientation=str(self.cur_orientation.value))
            draw(headers, heads)
        for i, values in enumerate(rows):
            faces = [
                (col_styles or {}).get(j) or (styles[i] if styles else None)
                for j in range(len(widths))
            ]
            draw(values, faces, (247, 247, 247) if i % 2 == 0 else None)
        self.set_text_color(*DARK)
        self.font(size)
        self.ln(2)

    def _wrap(self, text: str, width: float) -> list[str]:
        """``text`` broken into lines no wider than ``width`` mm in the current font: at
        spaces, at its own line breaks, and inside a word only when the word alone is wider."""
        out: list[str] = []
        space = self.get_string_width(" ")
        for paragraph in text.split("\n"):
            line, used = "", 0.0
            for word in paragraph.split(" "):
                w = self.get_string_width(word)
                if line and used + space + w <= width:
                    line, used = f"{line} {word}", used + space + w
                    continue
                if line:
                    out.append(line)
                while w > width and len(word) > 1:  # a word wider than the column
                    cut = len(word)
                    while cut > 1 and self.get_string_width(word[:cut]) > width:
                        cut -= 1
                    out.append(word[:cut])
                    word = word[cut:]
                    w = self.get_string_width(word)
                line, used = word, w
            out.append(line)
        return out or [""]

    def key_values(
        self,
        pairs: Sequence[tuple[str, Any]],
        key_width: float = 42,
        mono_keys: frozenset[str] = frozenset(),
    ) -> None:
        width = self.w - self.l_margin - self.r_margin
        for key, value in pairs:
            self.font(8.5, "B")
            self.set_text_color(*GREY)
            self.cell(key_width, 4.8, self.t(key))
            self.set_text_color(*DARK)
            self.font(7.5 if key in mono_keys else 8.5, mono=key in mono_keys)
            self.multi_cell(
                width - key_width, 4.8, self.t(value), new_x="LMARGIN", new_y="NEXT", align="L"
            )

    # ---------------------------------------------------------------- pictures
    def pictures(
        self,
        items: Sequence[tuple[str, Path]],
        columns: int = 3,
        gap: float = 4.0,
        title: str | None = None,
    ) -> None:
        """Rows of captioned pictures, ``columns`` per row, scaled to the width.

        ``title`` is set above the first row and kept on the same page.
        """
        width = self.w - self.l_margin - self.r_margin
        cell_w = (width - gap * (columns - 1)) / columns
        for start in range(0, len(items), columns):
            row = items[start : start + columns]
            heights = [cell_w * _aspect(path) for _, path in row]
            row_h = max(heights) + 5
            title_h = 6.0 if title and start == 0 else 0.0
            if self.get_y() + title_h + row_h > self.page_break_trigger:
                self.add_page()
            if title and title_h:
                self.subheading(title)
            top = self.get_y()
            for k, ((caption, path), h) in enumerate(zip(row, heights, strict=True)):
                self._place(self.l_margin + k * (cell_w + gap), top, cell_w, h, caption, path)
            self.set_xy(self.l_margin, top + row_h + 1)

    def picture(self, caption: str, path: Path, min_scale: float = 0.6) -> None:
        """One captioned picture the width of the page, shrunk (to no less than ``min_scale``
        of that width, centred) to stay on the current page; else on the next page."""
        width = self.w - self.l_margin - self.r_margin
        full_h = width * _aspect(path)
        scale = min(1.0, (self.page_break_trigger - self.get_y() - 6.0) / full_h)
        if scale < min_scale:
            self.add_page()
            scale = 1.0
        w, h = width * scale, full_h * scale
        top = self.get_y()
        self._place(self.l_margin + (width - w) / 2, top, w, h, caption, path)
        self.set_xy(self.l_margin, top + h + 6.0)

    def picture_at(self, x: float, top: float, width: float, caption: str, path: Path) -> float:
        """``path`` drawn ``width`` mm wide at ``(x, top)``, captioned; returns the y below
        its caption (the cursor is left there, at the left margin)."""
        height = width * _aspect(path)
        self._place(x, top, width, height, caption, path)
        self.set_xy(self.l_margin, top + height + 6.0)
        return top + height + 6.0

    def _place(self, x: float, top: float, w: float, h: float, caption: str, path: Path) -> None:
        """``path`` drawn in the ``w`` × ``h`` mm box at ``(x, top)``, ``caption`` centred
        under it; a missing file is a framed note."""
        if path.is_file():
            self.image(str(path), x=x, y=top, w=w, h=h, alt_text=self.t(caption))
        else:
            self.set_draw_color(*GREY)
            self.rect(x, top, w, h)
            self.set_xy(x + 2, top + h / 2 - 4)
            self.font(7.5)
            self.multi_cell(w - 4, 4, self.t(f"picture not found: {path}"), align="C")
        self.set_xy(x, top + h + 0.5)
        self.font(7.5)
        self.set_text_color(*GREY)
        self.cell(w, 4, self.t(caption), align="C")
        self.set_text_color(*DARK)


def _aspect(path: Path) -> float:
    """Height / width of a picture (0.75 for a missing file, so the gap keeps its place)."""
    try:
        with Image.open(path) as img:
            return img.height / img.width
    except OSError:
        return 0.75


def view_caption(view: str) -> str:
    return {"three_quarter": "three-quarter (right)", "side": "side (right)"}.get(view, view)


def picture_groups(pictures: dict[str, str], base: Path) -> dict[str, list[tuple[str, Path]]]:
    """Sort picture keys into the report's groups (views in front, side, three-quarter order)."""
    groups: dict[str, list[tuple[str, Path]]] = {}
    rank = {v: i for i, v in enumerate(VIEWS)}
    used = set()
    for prefix, title in GROUPS:
        keys = [k for k in pictures if k.startswith(prefix) and k not in used]
        keys.sort(key=lambda k: rank.get(k[len(prefix) :], len(rank)))
        if keys:
            groups[title] = [
                (view_caption(k[len(prefix) :]), resolve_picture(pictures[k], base)) for k in keys
            ]
            used.update(keys)
    for key in pictures:
        if key not in used:
            groups.setdefault(key, []).append(
                (key.replace("_", " "), resolve_picture(pictures[key], base))
            )
    return groups


def resolve_picture(path: str, base: Path) -> Path:
    """A picture's path from the report: relative paths are relative to ``base``."""
    p = Path(path)
    return p if p.is_absolute() else base / p
