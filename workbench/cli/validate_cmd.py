"""``workbench validate MANIFEST.csv --out DIR``: accuracy on real skull/skin pairs.

Writes ``DIR/results.csv``, ``DIR/results.md``, ``DIR/results.pdf`` (with
signed-distance pictures on the true skin), ``DIR/features.csv`` for cases with
true landmarks (``truth_landmarks``) and a folder per case with the
reconstruction (the same files ``workbench reconstruct`` writes) and the
extracted surfaces.  See :mod:`workbench.services.validation.run` for the
manifest columns and the method.

Text from the manifest reaches the tables guarded: every CSV cell through
:func:`workbench.core.table_cells.csv_cell` (no spreadsheet formulas), every
Markdown cell through :func:`workbench.core.table_cells.md_cell`, both applied by the
writers of :mod:`workbench.reporting.validation_report`.
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

import numpy as np


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "validate",
        help="reconstruct real skulls and score them against their true skin",
        description="Run the reconstruction on every case of a manifest (CSV columns: id, skull, "
        "truth, units, mask, anterior, superior, left, sex, build, tissue, template, "
        "bone_iso, skin_iso, subject, truth_landmarks; skull and truth may be meshes or CT "
        "volumes) and score "
        "it with the project's metric beside a uniform 6 mm offset of the bone.",
    )
    p.add_argument("manifest", type=Path)
    p.add_argument(
        "--out",
        type=Path,
        required=True,
        help="output folder; it must not hold the manifest or any case's files (it is "
        "replaced as a whole; with --force a previous run's extracted surfaces "
        "and reference packs are reused)",
    )
    p.add_argument(
        "--leave-one-out",
        action="store_true",
        help="also reconstruct each case with reference heads built from all other "
        "cases (their per-vertex median), never its own",
    )
    p.add_argument(
        "--identity",
        action="store_true",
        help="also the identity test: a reference built from the case's own skin and "
        "bone, tissue model 'reference'",
    )
    p.add_argument("--cases", default=None, metavar="ID,ID", help="only these case ids")
    p.add_argument("--no-pictures", action="store_true")
    from workbench.cli.common import add_force_option

    add_force_option(p, folder=True)
    p.set_defaults(handler=run)


def run(args: argparse.Namespace) -> int:
    from workbench.core.errors import InputError
    from workbench.io.outputs import check_output_folder, staged_folder
    from workbench.services.validation.run import read_manifest, reuse_caches, validation_inputs

    cases = read_manifest(args.manifest)
    if args.cases:
        wanted = [c.strip() for c in args.cases.split(",") if c.strip()]
        unknown = sorted(set(wanted) - {c.case_id for c in cases})
        if unknown:
            raise InputError(args.manifest, f"no cases {', '.join(unknown)}")
        cases = [c for c in cases if c.case_id in wanted]
    inputs = [args.manifest, *validation_inputs(cases)]
    check_output_folder(args.out, inputs, args.force)  # the cases take minutes each
    with staged_folder(args.out, args.force, inputs, notify=print) as out:
        reuse_caches(args.out, out)
        ok = _run(args, cases, out)
    final = args.out
    print(f"wrote {final / 'results.csv'}, {final / 'results.md'}, {final / 'results.pdf'}")
    return 0 if ok else 2


def _run(args: argparse.Namespace, cases: list, out: Path) -> bool:
    """Every case, the tables and the PDF, into the staged folder ``out``."""
    from workbench import __version__
    from workbench.core.safe_names import child_path
    from workbench.reporting.validation_report import (
        band_rows,
        feature_rows,
        markdown,
        rows,
        write_csv,
        write_pdf,
    )
    from workbench.services.templates.regions import REGION_NAMES
    from workbench.services.validation.run import run_validation

    pictures: dict[tuple[str, str], list[tuple[str, Path]]] = {}

    def on_case(res: Any, job: Any, label: str) -> None:
        if res.status != "ok":
            print(f"  {res.case_id} [{label}]: failed: {res.error}")
            return
        for s in res.scores:
            f = s.figures
            print(
                f"  {res.case_id} [{s.name}]: {f['pct_within_2_5mm']:.1f} % within 2.5 mm, "
                f"mean |d| {f['mean_abs_mm']:.2f} mm, signed {f['signed_mean_mm']:+.2f} mm "
                f"(n = {f['n']})"
            )
        if not args.no_pictures:
            pictures[(res.case_id, label)] = _pictures(res, child_path(out, res.case_id), label)

    results = run_validation(
        cases,
        out,
        leave_one_out=args.leave_one_out,
        identity=args.identity,
        progress=lambda m: print(f"  {m}"),
        on_case=on_case,
        staged=True,
    )
    credits = sorted({c for case in cases for p in (case.skull, case.truth) if (c := _credit(p))})
    table = rows(results, REGION_NAMES)
    write_csv(table, out / "results.csv")
    bands = band_rows(results)
    if bands:  # the uncertainty band's coverage of the true skin, per build and region
        write_csv(bands, out / "bands.csv")
    features = feature_rows(results)
    if features:  # cases with true landmarks: per-feature errors of every method and rule
        write_csv(features, out / "features.csv")
    tmp = out / "results.md.part"
    tmp.write_text(markdown(results, REGION_NAMES, credits), encoding="utf-8")
    tmp.replace(out / "results.md")
    write_pdf(
        results,
        REGION_NAMES,
        out / "results.pdf",
        pictures,
        credits,
        software=f"workbench {__version__}",
    )
    return all(r.status == "ok" for r, _ in results)


def _credit(path: Path) -> str | None:
    """The credit line a data source asks for (Visible Human data: NLM's), if any."""
    from workbench.io import samples

    for name in ("credit_for", "credit_for_mesh_file"):
        fn = getattr(samples, name, None)
        if fn is not None:
            try:
                found = fn(path)
            except (OSError, ValueError):
                found = None
            if found:
                return found
    return None


def _pictures(res: Any, folder: Path, label: str) -> list[tuple[str, Path]]:
    """Signed-distance heat maps on the true skin for each method of a case."""
    from workbench.core.errors import WorkbenchError
    from workbench.io.meshes import read_mesh

    try:
        from workbench.render.heatmap import render_heatmap
    except ImportError:  # pragma: no cover - pyvista is a dependency
        return []
    truth = read_mesh(res.files["truth"], units="mm").mesh
    items = []
    for s in res.scores:
        values = np.full(truth.n_vertices, np.nan)
        values[res.truth_ids] = s.signed_mm
        path = folder / "pictures" / f"{label}_{s.name}.png"
        path.parent.mkdir(parents=True, exist_ok=True)
        try:
            render_heatmap(
                truth,
                values,
                path,
                views=("front", "side"),
                clim=(-8.0, 8.0),
                title=f"{res.case_id}: {s.name}",
                frame=(tuple(res.anterior), tuple(res.superior)),
            )
        except (RuntimeError, OSError, ValueError, WorkbenchError) as exc:
            print(f"  note: no picture for {res.case_id} {s.name} ({exc})")
            continue
        items.append((s.name.replace("_", " "), path))
    return items
