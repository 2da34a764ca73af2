"""``workbench demo``: the main job — skull to face — on the built-in default case.

1. **Built-in case** (no download): the project's own female reference skull
   (cranium, mandible and teeth as one mesh, written to ``builtin/skull.ply``)
   is reconstructed with the *male* reference head: the reference skull
   registered densely onto it, the head carried and its tissue calibrated to
   the T-Table, Kähler's guides and a 20-member depth ensemble.  The female
   reference skin is the known truth, so the report carries validation
   figures.
2. **headsq** (public CT sample, when available): bone and skin surfaces are
   extracted from the CT, the bone is reconstructed the same way and the
   result is scored against the CT's own skin (the metric of VALIDATION.md)
   beside a uniform 6 mm offset of the bone.

Everything is written to ``--out`` (default ``demo_out/``) with a summary.
The folder is written as a whole (a failed or interrupted demo leaves the
previous one as it was).  A previous demo's folder is replaced without
``--force``: everything in it is made again from built-in data, so keeping
each run would only pile up copies.  Any other non-empty folder is refused
unless ``--force``, which keeps it as ``DIR.1``.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

from workbench.cli.common import add_force_option, mesh_summary, progress_printer, write_json
from workbench.io.meshes import write_mesh
from workbench.io.samples import fetch, registry
from workbench.services.ct.ct_mesh import mesh_from_ct


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "demo", help="run the main pipeline on the built-in default case", description=__doc__
    )
    p.add_argument("--out", type=Path, default=Path("demo_out"), help="output folder")
    p.add_argument(
        "--no-picture",
        "--no-pictures",
        dest="no_picture",
        action="store_true",
        help="skip the rendered pictures",
    )
    p.add_argument("--ensemble", type=int, default=20, help="ensemble size (0 = none)")
    p.add_argument("--skip-headsq", action="store_true", help="only the built-in case")
    add_force_option(p, folder=True)
    p.set_defaults(handler=run)


#: written into every demo folder, so the next demo knows it may replace it
DEMO_MARK = ".workbench-demo"


def _is_demo_output(folder: Path) -> bool:
    """A folder an earlier ``workbench demo`` wrote (its mark, or its summary)."""
    if (folder / DEMO_MARK).is_file():
        return True
    import json

    try:
        summary = json.loads((folder / "summary.json").read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return False
    return isinstance(summary, dict) and "builtin" in summary and "seconds_total" in summary


def _shown(value, temp: Path, final: Path):
    """``value`` with the staged folder's name in strings replaced by the final one."""
    if isinstance(value, str):
        return value.replace(str(temp), str(final))
    if isinstance(value, dict):
        return {k: _shown(v, temp, final) for k, v in value.items()}
    if isinstance(value, list):
        return [_shown(v, temp, final) for v in value]
    return value


def run(args: argparse.Namespace) -> int:
    import os

    from workbench.io.outputs import staged_folder

    started = time.perf_counter()
    final = Path(os.path.abspath(args.out))
    # A previous demo is replaced (no backup) without --force; see the module docstring.
    previous_demo = _is_demo_output(final)
    replace_demo = previous_demo and not args.force
    with staged_folder(
        final, args.force or previous_demo, discard_existing=replace_demo, notify=print
    ) as out:
        (out / DEMO_MARK).write_text(
            "written by workbench demo; the next demo replaces this folder\n", encoding="utf-8"
        )
        summary: dict = {"builtin": _builtin(out / "builtin", args)}
        if not args.skip_headsq:
            summary["headsq"] = _headsq(out / "headsq", args)
        summary["seconds_total"] = round(time.perf_counter() - started, 2)
        summary = _shown(summary, out, final)
        write_json(summary, out / "summary.json")
    print(f"wrote {args.out / 'summary.json'} ({summary['seconds_total']} s)")
    return 0


def _figures(report: dict, folder: Path) -> dict:
    v = report.get("validation") or {}
    return {
        "folder": str(folder),
        "report": "report.pdf",
        "fit": {
            k: report["fit"].get(k)
            for k in (
                "max_tip_error_mm",
                "min_tissue_mm",
                "penetrating_vertices",
                "suggested_landmarks",
                "absent_landmarks",
            )
        },
        "ensemble_spread_mm": (report.get("ensemble") or {}).get("spread_mm"),
        "validation": {
            **{
                k: v.get(k)
                for k in (
                    "mean_abs_mm",
                    "rms_mm",
                    "signed_mean_mm",
                    "pct_within_2_5mm",
                    "pct_within_5mm",
                )
            },
            "uniform_6mm_offset": {
                k: (v.get("baseline") or {}).get(k) for k in ("mean_abs_mm", "pct_within_2_5mm")
            },
        }
        if v
        else None,
        "seconds": report.get("_seconds"),
        "picture": (report.get("pictures") or {}).get("face_skull_three_quarter"),
    }


def _builtin(folder: Path, args: argparse.Namespace) -> dict:
    from workbench.cli.reconstruct_cmd import execute
    from workbench.services.reconstruction.job import JobSettings
    from workbench.services.templates.cache import reference_head
    from workbench.services.templates.reference_parts import skull_surface

    print("built-in case: the female reference skull, reconstructed with the male head")
    folder.mkdir(parents=True, exist_ok=True)
    female = reference_head("female")
    skull = write_mesh(folder / "skull.ply", skull_surface(female))
    truth = write_mesh(folder / "truth_skin.ply", female.skin)
    settings = JobSettings(sex="male", ensemble=args.ensemble, orientation=((0, 0, 1), (0, 1, 0)))
    # the demo's own folder (staged by run()): the skull written above stays beside the face
    report = execute(
        skull, settings, folder, truth=truth, pictures=not args.no_picture, quiet=True, staged=True
    )
    return _figures(report, folder)


def _headsq(folder: Path, args: argparse.Namespace) -> dict | None:
    from workbench.cli.reconstruct_cmd import execute
    from workbench.core.errors import WorkbenchError
    from workbench.services.reconstruction.job import JobSettings

    try:
        ct = fetch("headsq")
    except (WorkbenchError, OSError) as exc:
        print(f"headsq sample not available ({exc}); skipped")
        return None
    print("headsq: CT -> bone and skin surfaces -> reconstruction from the bone")
    folder.mkdir(parents=True, exist_ok=True)
    surfaces = {}
    for tissue in ("bone", "skin"):
        result = mesh_from_ct(ct, tissue=tissue, progress=progress_printer())
        surfaces[tissue] = {
            "file": write_mesh(folder / f"{tissue}.ply", result.mesh).name,
            **mesh_summary(result.mesh),
            "iso": result.iso,
        }
    anatomy = registry()["headsq"].anatomy or {}
    orientation = (anatomy["anterior"], anatomy["superior"], anatomy["left"])
    settings = JobSettings(sex="male", ensemble=args.ensemble, orientation=orientation)
    report = execute(
        folder / "bone.ply",
        settings,
        folder / "reconstruction",
        truth=folder / "skin.ply",
        pictures=not args.no_picture,
        quiet=True,
        staged=True,
    )
    return {"surfaces": surfaces, **_figures(report, folder / "reconstruction")}


def _picture(meshes: dict, path: Path) -> str | None:
    try:
        from workbench.render.snapshots import render_surfaces
    except ImportError as exc:  # pragma: no cover - pyvista is a dependency
        print(f"  note: no picture ({exc})")
        return None
    try:
        anatomy = registry()["headsq"].anatomy or {}
        render_surfaces(
            [(meshes["bone"], "ivory", 1.0), (meshes["skin"], "peachpuff", 0.35)],
            path,
            views=("front", "three_quarter", "side"),
            # with the subject's left: headsq's file is a mirror image, shown flipped
            orientation=(anatomy["anterior"], anatomy["superior"], anatomy["left"]),
        )
    except (RuntimeError, OSError, ValueError) as exc:  # a missing GL stack must not fail the job
        print(f"  note: no picture: off-screen rendering unavailable ({type(exc).__name__}: {exc})")
        return None
    print(f"  picture -> {path}")
    return path.name
