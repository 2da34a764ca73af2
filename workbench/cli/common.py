"""Helpers shared by the sub-commands: unit options, mesh loading, output."""

from __future__ import annotations

import argparse
import json
import math
import sys
from collections.abc import Mapping
from pathlib import Path
from typing import TYPE_CHECKING, Any

from workbench.core.errors import WorkbenchError
from workbench.core.mesh import Mesh
from workbench.core.units import UNIT_SCALES, check_units_choice, resolve_units
from workbench.io.atomic import json_default, write_json_atomic
from workbench.io.meshes import MeshReadResult, read_mesh
from workbench.io.samples import resolve_input

if TYPE_CHECKING:
    from workbench.model.appearance import Appearance


def add_units_options(parser: argparse.ArgumentParser) -> None:
    """``--units`` and ``--scale`` for every command that reads a mesh."""
    parser.add_argument(
        "--units",
        choices=["auto", *UNIT_SCALES],
        default="auto",
        help="units of the numbers in the mesh file (mesh files carry none). 'auto' accepts "
        "the file only if its size looks like millimetres and otherwise stops with an "
        "explanation; nothing is ever rescaled silently (default: auto)",
    )
    parser.add_argument(
        "--scale",
        type=float,
        default=None,
        metavar="FACTOR",
        help="explicit factor from file units to mm (instead of --units)",
    )


def add_force_option(parser: argparse.ArgumentParser, folder: bool = False) -> None:
    """``--force``: replace an existing output, keeping the old one as a numbered backup."""
    kept = "DIR.1, DIR.2 ..." if folder else "NAME.1.EXT, NAME.2.EXT ..."
    parser.add_argument(
        "--force",
        action="store_true",
        help=f"replace an existing output; the old one is kept as {kept}. Inputs are never "
        "replaced, not even with --force",
    )


def output_path(path: Path, args: argparse.Namespace, *inputs: Any):
    """Context manager yielding ``path`` to write atomically (see ``workbench.io.outputs``).

    Refuses an output that is one of ``inputs`` (paths or ``sample:NAME``), or
    that exists unless ``--force`` (then kept as ``NAME.1.EXT``).
    """
    from workbench.io.outputs import output_file

    return output_file(path, _input_paths(inputs), getattr(args, "force", False), notify=print)


def _input_paths(inputs: tuple[Any, ...]) -> list[Path]:
    found = []
    for item in inputs:
        if item is None:
            continue
        text = str(item)
        if text.startswith("sample:"):
            try:
                found.append(resolve_input(text))
            except (WorkbenchError, OSError):  # an unknown sample is reported by its reader
                continue
        else:
            found.append(Path(text))
    return found


def input_paths(*inputs: Any) -> list[Path]:
    """Inputs as paths (``sample:NAME`` resolved, None dropped), for the output checks."""
    return _input_paths(inputs)


def load_mesh(
    argument: str,
    args: argparse.Namespace,
    kind: str = "head",
    options: tuple[str, str] = ("--units", "--scale"),
    check_skull: bool = False,
) -> MeshReadResult:
    """Read a mesh (path or ``sample:NAME``) applying the user's units policy.

    Raises ``UnitsError`` when ``--units auto`` and the size does not look like mm,
    and ``InputError`` for both units and a scale (``options`` are their names), or,
    with ``check_skull``, a mesh that cannot be a skull in mm (size, triangles, topology).
    """
    path = resolve_input(argument)
    units = getattr(args, "units", "auto")
    scale = getattr(args, "scale", None)
    check_units_choice(units, scale, units_option=options[0], scale_option=options[1])
    result = read_mesh(path, units=units if scale is None else "auto", scale=scale, kind=kind)
    if scale is None and units == "auto":
        resolve_units(result.units, "auto", source=str(path))
    if check_skull:
        from workbench.services.case.input_checks import check_skull_mesh

        check_skull_mesh(result.mesh, path, units_note=result.units.confirmed)
    return result


def write_json(data: dict[str, Any], out: Path | None) -> None:
    if out is None:
        print(json.dumps(data, indent=2, default=json_default))
    else:
        out.parent.mkdir(parents=True, exist_ok=True)
        write_json_atomic(out, data)  # a full disk, Ctrl-C: the old file or the whole new one


def mesh_summary(mesh: Mesh) -> dict[str, Any]:
    """Counts, bounds, extent and area (mm); a value that is not finite is None (JSON null)."""
    lo, hi = mesh.bounds
    return {
        "n_vertices": mesh.n_vertices,
        "n_faces": mesh.n_faces,
        "bounds_mm": [_finite_or_none(lo), _finite_or_none(hi)],
        "extent_mm": _finite_or_none(hi - lo),
        "area_mm2": _finite_or_none(mesh.area),
    }


def _finite_or_none(value: Any) -> Any:
    """Numbers as they are, NaN and infinities as None (valid JSON), arrays element-wise."""
    if hasattr(value, "tolist"):
        value = value.tolist()
    if isinstance(value, list):
        return [_finite_or_none(v) for v in value]
    if isinstance(value, float) and not math.isfinite(value):
        return None
    return value


def progress_printer(enabled: bool = True):
    """A ``progress(step, fraction)`` callback printing to stderr."""
    last: dict[str, str | None] = {"step": None}

    def report(step: str, fraction: float) -> None:
        if not enabled:
            return
        if step != last["step"] and step != "done":
            print(f"    {step} ...", file=sys.stderr, flush=True)
            last["step"] = step

    return report


def self_check_status(command: str, check: Mapping[str, Any] | None) -> int:
    """``EXIT_CHECK`` (with one line on stderr saying why) when the registration's
    self-check asks for a check, else 0."""
    from workbench.services.registration.skull_check import EXIT_CHECK

    if not (check and check.get("outcome") == "check"):
        return 0
    reasons = list(check.get("reasons", ())) or ["the registration's self-check"]
    print(
        f"workbench {command}: outputs written, but check them before use (exit "
        f"{EXIT_CHECK}): {reasons[0]}",
        file=sys.stderr,
    )
    return EXIT_CHECK


def print_self_check(check: Mapping[str, Any] | None) -> None:
    """The registration's self-check, when it asks for a check: one ``CHECK:`` line per
    reason, worst first, before the command's other results (issue 28)."""
    if check and check.get("outcome") == "check":
        for reason in check.get("reasons", ()):
            print(f"CHECK: {reason}")


def add_style_options(parser: argparse.ArgumentParser, note: str = "") -> None:
    """``--hair``, ``--brows``, ``--beard`` and ``--moustache STYLE`` (the library of
    :mod:`workbench.core.grooming`; default None: the case's, else none); ``note`` is
    added to each help text."""
    from workbench.core.grooming import KINDS, style_names

    for kind in KINDS:
        parser.add_argument(
            f"--{kind}",
            choices=list(style_names(kind)),
            default=None,
            metavar="STYLE",
            help=f"{note}{kind} style: {', '.join(style_names(kind))} (an artistic addition, "
            "not evidence; default: the case's, else none)",
        )


def case_appearance(spec: str) -> Appearance | None:
    """The appearance kept in a reconstruction folder's ``case.fcase``, if it has one
    (``reference:...`` heads and folders without a case file have none)."""
    if spec.startswith("reference:"):
        return None
    path = Path(spec) / "case.fcase"
    if not path.is_file():
        return None
    from workbench.io.case_file import load_case

    return load_case(path).case.appearance


def chosen_appearance(args: argparse.Namespace) -> Appearance | None:
    """The case's appearance (:func:`case_appearance` of ``args.head``) with the options'
    changes (``--skin-tone``, ``--iris``, ``--hair``, ``--brows``, ``--beard``,
    ``--moustache``); None when neither gives one (then plain tone and iris defaults
    apply, as before).  ``workbench portrait`` and ``workbench animate`` share it."""
    from workbench.core.grooming import KINDS
    from workbench.model.appearance import Appearance

    base = case_appearance(str(args.head))
    styles = {k: getattr(args, k) for k in KINDS if getattr(args, k, None) is not None}
    if base is None and not styles:
        return None
    look = base if base is not None else Appearance()
    if getattr(args, "skin_tone", None) is not None:
        look = look.with_tone(args.skin_tone)
    if getattr(args, "iris", None) is not None:
        look = look.replaced(iris=args.iris)
    for kind, style in styles.items():
        look = look.with_style(kind, style)
    return look
