"""``workbench validate MANIFEST.csv --out DIR``: accuracy on real skull/skin pairs.

Writes ``DIR/results.csv``, ``DIR/results.md``, ``DIR/results.pdf`` (with
signed-distance pictures on the true skin), ``DIR/features.csv`` for cases with
true landmarks (``truth_landmarks``) and a folder per case with the
reconstruction (the same files ``workbench reconstruct`` writes) and the
extracted surfaces (:func:`workbench.pipelines.validate.validate_to_folder`).
See :mod:`workbench.services.validation.run` for the manifest columns and the method.

Text from the manifest reaches the tables guarded: every CSV cell through
:func:`workbench.core.table_cells.csv_cell` (no spreadsheet formulas), every
Markdown cell through :func:`workbench.core.table_cells.md_cell`, both applied by the
writers of :mod:`workbench.reporting.validation_report`.
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from workbench.pipelines.outcome import JobOutcome


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


def run(args: argparse.Namespace) -> JobOutcome:
    """The study's folder; exit status 2 when a case failed (the others are still scored)."""
    from workbench.pipelines.batch.figures import validate_figures
    from workbench.pipelines.outcome import JobOutcome
    from workbench.pipelines.validate import validate_to_folder

    wanted = [c.strip() for c in args.cases.split(",") if c.strip()] if args.cases else None
    done = validate_to_folder(
        args.manifest,
        args.out,
        case_ids=wanted,
        leave_one_out=args.leave_one_out,
        identity=args.identity,
        pictures=not args.no_pictures,
        force=args.force,
        say=print,
        notify=print,
    )
    final = args.out
    print(f"wrote {final / 'results.csv'}, {final / 'results.md'}, {final / 'results.pdf'}")
    return JobOutcome(0 if done.ok else 2, validate_figures(done.table))
