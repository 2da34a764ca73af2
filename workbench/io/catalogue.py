"""The landmark catalogue: one code system for skin and skull landmarks.

The catalogue lives in ``data_tables/landmarks/catalogue.csv`` with a
``catalogue.meta.json`` sidecar (citations).  A landmark is identified by
``(surface, code)``; bilateral codes end in ``_l`` / ``_r`` for the subject's
left / right.  The catalogue holds no coordinates, so it has no units or frame.

:meth:`LandmarkCatalogue.normalise` turns the spellings found in other tools
and papers (``exL``, ``Lex``, ``ex (left)``, ``mso'L``, ``ecm2(s)R``, Kähler's
``spm2*`` ...) into catalogue codes.
"""

from __future__ import annotations

import csv
import json
import os
import re
from collections.abc import Iterable
from dataclasses import dataclass, field
from pathlib import Path

from workbench.core.data_paths import data_tables_dir
from workbench.core.errors import InputError, LandmarkError
from workbench.core.landmarks import SURFACES

COLUMNS = (
    "surface",
    "code",
    "name",
    "side",
    "bilateral_pair",
    "partner",
    "definition",
    "aliases",
    "source",
)
SIDES = ("midline", "left", "right")
_SIDE_SUFFIX = {"left": "_l", "right": "_r"}
_SIDE_WORD = {"l": "left", "left": "left", "r": "right", "right": "right"}

# Side spellings, tried in order; each yields (base, side word).
_SIDE_PATTERNS = (
    re.compile(r"^(?P<base>.+?)\s*\(\s*(?P<side>left|right|l|r)\s*\)$", re.IGNORECASE),  # ex (left)
    re.compile(
        r"^(?P<base>.+?)[_\-\s.']+(?P<side>left|right|l|r)$", re.IGNORECASE
    ),  # ex_l ex-L ex'L
    re.compile(r"^(?P<base>.*[^\s_\-.])(?P<side>[LR])$"),  # exL ecm2(s)R
    re.compile(r"^(?P<side>left|right|l|r)[_\-\s.]+(?P<base>.+)$", re.IGNORECASE),  # L ex, left-ex
    re.compile(r"^(?P<side>[LR])(?P<base>[a-z].*)$"),  # Lex (Cliniface)
)
_PRIMES = ("'", "\u2019", "\u2032")


def split_side(label: str) -> list[tuple[str, str]]:
    """Every ``(base, side)`` reading of ``label`` (side is ``"left"``/``"right"``).

    Pure string handling, no catalogue needed: ``"exL"`` → ``[("ex", "left")]``.
    """
    out = []
    for pattern in _SIDE_PATTERNS:
        m = pattern.match(label)
        if m:
            out.append((m["base"].strip(), _SIDE_WORD[m["side"].lower()]))
    return out


def _strip_primes(text: str) -> str:
    for p in _PRIMES:
        text = text.replace(p, "")
    return text


@dataclass(frozen=True)
class CatalogueEntry:
    """One row of the catalogue (see ``data_tables/landmarks/README.md``)."""

    surface: str
    code: str
    name: str
    side: str
    bilateral_pair: str
    partner: str
    definition: str
    aliases: tuple[str, ...]
    sources: tuple[str, ...]

    @property
    def is_bilateral(self) -> bool:
        return self.side != "midline"

    @property
    def display_name(self) -> str:
        """The name with its side when the name does not say it: ``"Alar curvature point,
        left"`` (the subject's left); a midline landmark's name as it is."""
        if self.side not in ("left", "right") or self.side in self.name.lower():
            return self.name
        return f"{self.name}, {self.side}"

    @property
    def base(self) -> str:
        """Code without the side suffix (``"ex_l"`` → ``"ex"``)."""
        return self.code[:-2] if self.is_bilateral else self.code


def _unique(index: dict) -> dict:
    """Keep only keys that point at exactly one code."""
    return {k: next(iter(v)) for k, v in index.items() if len(v) == 1}


@dataclass(frozen=True)
class LandmarkCatalogue:
    """All known landmarks, with lookups by code, alias, side and partner.

    Parameters
    ----------
    entries : tuple of CatalogueEntry
        In file order.
    sources : dict
        Citation key → full citation (from the meta sidecar).
    path : str
        Where the table was read from (for messages).
    """

    entries: tuple[CatalogueEntry, ...]
    sources: dict[str, str] = field(default_factory=dict, hash=False)
    path: str = ""
    _by_key: dict = field(init=False, repr=False, compare=False)
    _exact: dict = field(init=False, repr=False, compare=False)
    _folded: dict = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        object.__setattr__(self, "entries", tuple(self.entries))
        by_key = {(e.surface, e.code): e for e in self.entries}
        exact: dict = {}
        folded: dict = {}
        for e in self.entries:
            short = re.sub(r"\s*\([^)]*\)$", "", e.name)
            names = [e.name, *([short] if short != e.name else []), *e.aliases]
            side = e.side if e.is_bilateral else None
            keys: list[tuple[str, str, str | None]] = (
                [(e.surface, e.code, None)]
                if side is None
                else [(e.surface, e.code, "*"), (e.surface, e.base, side)]
            )
            for alias in names:
                if side is None:
                    keys.append((e.surface, alias, None))
                    continue
                readings = [r for r in split_side(alias) if r[1] == side]
                keys.append((e.surface, alias, "*") if readings else (e.surface, alias, side))
                keys += [(e.surface, b, s) for b, s in readings]
            for surface, text, s in keys:
                exact.setdefault((surface, text, s), set()).add(e.code)
                if len(text) > 1:  # 'A' / 'B' mean cephalometric points elsewhere: no folding
                    folded.setdefault((surface, text.lower(), s), set()).add(e.code)
        object.__setattr__(self, "_by_key", by_key)
        object.__setattr__(self, "_exact", _unique(exact))
        object.__setattr__(self, "_folded", _unique(folded))

    # ------------------------------------------------------------ lookups
    def get(self, code: str, surface: str) -> CatalogueEntry | None:
        """The entry for ``(surface, code)``, or None."""
        return self._by_key.get((surface, code))

    def entry(self, code: str, surface: str) -> CatalogueEntry:
        """Like :meth:`get` but raises :class:`LandmarkError` naming the code."""
        e = self.get(code, surface)
        if e is None:
            raise LandmarkError(f"unknown {surface} landmark code {code!r}")
        return e

    def __contains__(self, key: object) -> bool:
        return key in self._by_key

    def codes(self, surface: str) -> tuple[str, ...]:
        """All codes on one surface, in catalogue order."""
        return tuple(e.code for e in self.entries if e.surface == surface)

    def partner(self, code: str, surface: str) -> str | None:
        """Code of the paired landmark on the other surface, or None."""
        return self.entry(code, surface).partner or None

    def mirror(self, code: str, surface: str | None = None) -> str:
        """Code of the same landmark on the other side; midline codes map to themselves."""
        surfaces = (surface,) if surface else SURFACES
        for s in surfaces:
            e = self.get(code, s)
            if e is not None:
                return e.bilateral_pair or e.code
        raise LandmarkError(f"unknown landmark code {code!r}")

    def normalise(self, label: str, surface: str) -> str:
        """Catalogue code for a label as written in a file or a paper.

        Accepts codes, names, aliases, T-Table primes (``se'``, ``mso'L``) and
        side spellings (``exL``, ``ex_L``, ``Lex``, ``L ex``, ``ex-l``,
        ``ex (left)``).  Raises :class:`LandmarkError` naming the label.
        """
        if surface not in SURFACES:
            raise ValueError(f"surface must be one of {SURFACES}, got {surface!r}")
        text = " ".join(str(label).split())
        variants = [text] + ([_strip_primes(text)] if _strip_primes(text) != text else [])
        for v in variants:
            code = self._lookup(v, surface)
            if code is not None:
                return code
        raise LandmarkError(f"unknown {surface} landmark label {label!r}")

    def _lookup(self, text: str, surface: str) -> str | None:
        if (surface, text) in self._by_key:
            return text
        for index, t in ((self._exact, text), (self._folded, text.lower())):
            for side in (None, "*"):
                if (surface, t, side) in index:
                    return index[(surface, t, side)]
        found = []
        for base, side in split_side(text):
            base = _strip_primes(base)
            for index, b in ((self._exact, base), (self._folded, base.lower())):
                code = index.get((surface, b, side))
                if code is not None:
                    found.append(code)
                    break
        if len(set(found)) > 1:
            raise LandmarkError(
                f"ambiguous {surface} landmark label {text!r}: "
                f"could be {', '.join(sorted(set(found)))}"
            )
        return found[0] if found else None


# ---------------------------------------------------------------- loading
def default_catalogue_path() -> Path:
    """``data_tables/landmarks/catalogue.csv`` of the installed wheel or the checkout."""
    return data_tables_dir() / "landmarks" / "catalogue.csv"


_CACHE: dict[tuple[str, int, int], LandmarkCatalogue] = {}


def load_catalogue(path: str | os.PathLike[str] | None = None) -> LandmarkCatalogue:
    """Read and check the catalogue table (cached per file version).

    Parameters
    ----------
    path : path, optional
        CSV file; default :func:`default_catalogue_path`.  The sidecar
        ``<stem>.meta.json`` next to it is read when present.

    Raises
    ------
    InputError
        Missing file, wrong columns, or an inconsistent table (duplicate or
        dangling codes, asymmetric pairs, undefined citation keys).
    """
    csv_path = Path(path) if path is not None else default_catalogue_path()
    try:
        st = csv_path.stat()
    except OSError:
        raise InputError(csv_path, "landmark catalogue not found") from None
    key = (str(csv_path.resolve()), st.st_mtime_ns, st.st_size)
    if key not in _CACHE:
        _CACHE[key] = _read(csv_path)
    return _CACHE[key]


def read_table_rows(path: Path, columns: tuple[str, ...]) -> list[dict[str, str]]:
    """Rows of a UTF-8 CSV table whose header must be exactly ``columns``.

    InputError naming ``path`` for wrong columns or an unreadable file.
    """
    try:
        with open(path, newline="", encoding="utf-8") as fh:
            reader = csv.DictReader(fh)
            if tuple(reader.fieldnames or ()) != columns:
                raise InputError(
                    path,
                    f"columns must be {', '.join(columns)}; "
                    f"found {', '.join(reader.fieldnames or ())}",
                )
            return list(reader)
    except (UnicodeDecodeError, csv.Error) as exc:
        raise InputError(path, f"not a readable CSV table ({exc})") from None


def _read(csv_path: Path) -> LandmarkCatalogue:
    rows = read_table_rows(csv_path, COLUMNS)
    meta_path = csv_path.with_name(csv_path.name.removesuffix(".csv") + ".meta.json")
    sources: dict[str, str] | None = None
    if meta_path.exists():
        try:
            sources = dict(json.loads(meta_path.read_text(encoding="utf-8"))["sources"])
        except (ValueError, KeyError, TypeError) as exc:
            raise InputError(meta_path, f"not a catalogue meta file ({exc})") from None
    entries = [_entry(csv_path, i, row, sources) for i, row in enumerate(rows, start=2)]
    _check(csv_path, entries)
    return LandmarkCatalogue(tuple(entries), sources or {}, str(csv_path))


def _split(text: str | None) -> tuple[str, ...]:
    return tuple(p.strip() for p in (text or "").split(";") if p.strip())


def _entry(path: Path, line: int, row: dict, sources: dict | None) -> CatalogueEntry:
    e = CatalogueEntry(
        surface=row["surface"].strip(),
        code=row["code"].strip(),
        name=row["name"].strip(),
        side=row["side"].strip(),
        bilateral_pair=row["bilateral_pair"].strip(),
        partner=row["partner"].strip(),
        definition=row["definition"].strip(),
        aliases=_split(row["aliases"]),
        sources=_split(row["source"]),
    )
    problem = None
    if e.surface not in SURFACES:
        problem = f"surface must be skin or skull, got {e.surface!r}"
    elif e.side not in SIDES:
        problem = f"side must be midline, left or right, got {e.side!r}"
    elif e.is_bilateral != e.code.endswith(_SIDE_SUFFIX.get(e.side, "\0")):
        problem = f"code {e.code!r} does not match side {e.side!r}"
    elif not e.sources:
        problem = f"{e.code!r} cites no source"
    elif sources is not None and (missing := [s for s in e.sources if s not in sources]):
        problem = f"{e.code!r} cites undefined source key(s) {', '.join(missing)}"
    if problem:
        raise InputError(path, f"line {line}: {problem}")
    return e


def _check(path: Path, entries: Iterable[CatalogueEntry]) -> None:
    entries = list(entries)
    keys = {(e.surface, e.code): e for e in entries}
    problems = []
    if len(keys) != len(entries):
        seen: set[tuple[str, str]] = set()
        for e in entries:
            if (e.surface, e.code) in seen:
                problems.append(f"duplicate {e.surface} code {e.code!r}")
            seen.add((e.surface, e.code))
    other = {"skin": "skull", "skull": "skin"}
    for e in entries:
        pair = keys.get((e.surface, e.bilateral_pair))
        if e.is_bilateral and (
            pair is None or pair.bilateral_pair != e.code or pair.side == e.side
        ):
            problems.append(
                f"{e.surface} {e.code!r}: bilateral pair {e.bilateral_pair!r} is not its mirror"
            )
        if not e.is_bilateral and e.bilateral_pair:
            problems.append(f"{e.surface} {e.code!r}: midline point with a bilateral pair")
        if e.partner:
            p = keys.get((other[e.surface], e.partner))
            if p is None or p.partner != e.code:
                problems.append(
                    f"{e.surface} {e.code!r}: partner {e.partner!r} does not point back"
                )
        for alias in e.aliases:
            if e.is_bilateral and all(s != e.side for _, s in split_side(alias)):
                clash = keys.get((e.surface, alias + _SIDE_SUFFIX[e.side]))
            else:
                clash = keys.get((e.surface, alias))
            if clash is not None and clash is not e:
                problems.append(f"{e.surface} {e.code!r}: alias {alias!r} is another code")
    if problems:
        raise InputError(path, "inconsistent landmark catalogue: " + "; ".join(problems))
