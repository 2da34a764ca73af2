"""``workbench demo``: the main job on the built-in default case.

Until the skull-to-face reconstruction lands, the default case is the CT to
mesh pipeline on the public ``headsq`` CT sample: bone and skin surfaces, their
validation reports and dimensions, and a picture when an off-screen renderer
is available.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

from workbench.cli.common import mesh_summary, progress_printer, write_json
from workbench.io.meshes import write_mesh
from workbench.io.samples import fetch, registry
from workbench.services.ct_mesh import mesh_from_ct


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("demo", help="run the main pipeline on the built-in default case",
                       description=__doc__)
    p.add_argument("--out", type=Path, default=Path("demo_out"), help="output folder")
    p.add_argument("--no-picture", action="store_true", help="skip the rendered PNG")
    p.set_defaults(handler=run)


def run(args: argparse.Namespace) -> int:
    started = time.perf_counter()
    out: Path = args.out
    out.mkdir(parents=True, exist_ok=True)
    print("fetching sample:headsq (VTK head CT, 64x64x93, 3.2x3.2x1.5 mm)")
    ct = fetch("headsq")
    summary: dict = {"input": {"sample": "headsq", "path": str(ct)}, "surfaces": {}}
    meshes = {}
    for tissue in ("bone", "skin"):
        print(f"extracting the {tissue} surface")
        result = mesh_from_ct(ct, tissue=tissue, progress=progress_printer())
        path = out / f"headsq_{tissue}.ply"
        write_mesh(path, result.mesh)
        meshes[tissue] = result.mesh
        summary["surfaces"][tissue] = {
            "file": path.name, "iso": result.iso, "rule": result.rule, "frame": result.frame,
            **mesh_summary(result.mesh),
            "validation": result.validation.summary(),
            "seconds": round(result.timings_s.get("total", 0.0), 3),
        }
        print(f"  {result.validation.summary()}")
        print(f"  extent {[round(float(v), 1) for v in result.mesh.extent]} mm -> {path}")
    if not args.no_picture:
        summary["picture"] = _picture(meshes, out / "headsq_surfaces.png")
    summary["seconds_total"] = round(time.perf_counter() - started, 2)
    write_json(summary, out / "summary.json")
    print(f"wrote {out / 'summary.json'} ({summary['seconds_total']} s)")
    return 0


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
            path, views=("front", "three_quarter", "side"),
            orientation=(anatomy["anterior"], anatomy["superior"]),
        )
    except (RuntimeError, OSError, ValueError) as exc:  # a missing GL stack must not fail the job
        print(f"  note: no picture: off-screen rendering unavailable ({type(exc).__name__}: {exc})")
        return None
    print(f"  picture -> {path}")
    return path.name
