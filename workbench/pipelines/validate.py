"""A validation study, as a finished folder: every case reconstructed and scored, tables and PDF.

:func:`validate_to_folder` is ``workbench validate`` (and a batch row of
it): :func:`workbench.services.validation.run.run_validation` over the
manifest's cases (each case's reconstruction folder and extracted surfaces),
then ``results.csv``, ``results.md``, ``bands.csv``, ``features.csv`` and
``results.pdf`` with the signed-distance pictures on each true skin.  The
metric and the uniform-offset baseline are those of VALIDATION.md; distances
in mm, positive outside the true skin.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from workbench.pipelines.outcome import Say, quiet


@dataclass
class ValidationFolder:
    """What a validation run wrote: its results (case, label) and whether every case ran."""

    results: list[tuple[Any, str]]
    ok: bool
    out: Path
    #: one row per case and method, as written to ``results.csv``
    table: list[dict[str, Any]]


def validate_to_folder(
    manifest: Path,
    out: Path,
    *,
    case_ids: list[str] | None = None,
    leave_one_out: bool = False,
    identity: bool = False,
    pictures: bool = True,
    force: bool = False,
    say: Say = quiet,
    notify: Say | None = None,
) -> ValidationFolder:
    """Run the manifest's cases (or ``case_ids``) and write the study's folder ``out`` as a whole.

    ``out`` may not hold the manifest or a case's files; an existing folder is
    replaced only with ``force`` (its extracted surfaces and reference packs
    are reused).  ``say`` hears each step and each case's figures.
    """
    from workbench.core.errors import InputError
    from workbench.io.outputs import check_output_folder, staged_folder
    from workbench.services.validation.run import read_manifest, reuse_caches, validation_inputs

    cases = read_manifest(manifest)
    if case_ids:
        unknown = sorted(set(case_ids) - {c.case_id for c in cases})
        if unknown:
            raise InputError(manifest, f"no cases {', '.join(unknown)}")
        cases = [c for c in cases if c.case_id in case_ids]
    inputs = [manifest, *validation_inputs(cases)]
    check_output_folder(out, inputs, force)  # the cases take minutes each
    with staged_folder(out, force, inputs, notify=notify) as staged:
        reuse_caches(out, staged)
        results, table = _run(cases, staged, leave_one_out, identity, pictures, say)
    return ValidationFolder(results, all(r.status == "ok" for r, _ in results), out, table)


def _run(
    cases: list, out: Path, leave_one_out: bool, identity: bool, pictures: bool, say: Say
) -> tuple[list[tuple[Any, str]], list[dict[str, Any]]]:
    """Every case, the tables and the PDF, into the staged folder ``out``; the results and
    the table of ``results.csv``."""
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

    drawn: dict[tuple[str, str], list[tuple[str, Path]]] = {}

    def on_case(res: Any, job: Any, label: str) -> None:
        if res.status != "ok":
            say(f"  {res.case_id} [{label}]: failed: {res.error}")
            return
        for s in res.scores:
            f = s.figures
            say(
                f"  {res.case_id} [{s.name}]: {f['pct_within_2_5mm']:.1f} % within 2.5 mm, "
                f"mean |d| {f['mean_abs_mm']:.2f} mm, signed {f['signed_mean_mm']:+.2f} mm "
                f"(n = {f['n']})"
            )
        if pictures:
            drawn[(res.case_id, label)] = _pictures(res, child_path(out, res.case_id), label, say)

    results = run_validation(
        cases,
        out,
        leave_one_out=leave_one_out,
        identity=identity,
        progress=lambda m: say(f"  {m}"),
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
        drawn,
        credits,
        software=f"workbench {__version__}",
    )
    return results, table


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


def _pictures(res: Any, folder: Path, label: str, say: Say) -> list[tuple[str, Path]]:
    """Signed-distance heat maps on the true skin for each method of a case."""
    from workbench.core.errors import WorkbenchError
    from workbench.io.meshes import read_mesh
    from workbench.render.heatmap import render_heatmap

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
            say(f"  note: no picture for {res.case_id} {s.name} ({exc})")
            continue
        items.append((s.name.replace("_", " "), path))
    return items
