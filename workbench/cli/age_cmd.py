"""``workbench age``: a head changed to another age from anthropometric norms (Kähler §8.5).

HEAD is a template pack, a reconstruction folder (its ``head/`` pack) or
``reference:male`` / ``reference:female``.  The output folder holds the aged
pack(s) (``head/``, or ``head_<age>y/`` per age with ``--ages``),
``report.json`` and ``report.pdf`` (every measurement with its norms, z
before and after and residual; front and side pictures before and after)
and ``sequence.glb`` (the ages as morph targets of one mesh).  See
:mod:`workbench.services.age.change` for the method; units mm, Frankfort frame.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from workbench.cli.common import add_force_option, write_json
from workbench.core.errors import InputError
from workbench.pipelines.outcome import JobOutcome


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "age",
        help="change a head to another age (anthropometric norms by age and sex)",
        description="Age a head (growth or age regression): every facial measurement with "
        "norms keeps its z-score between the two ages, the head follows the "
        "head-circumference chart, and the whole head (skin, skull, teeth, eyes, muscles) is "
        "warped to the new landmarks. Writes template packs, report.json, report.pdf and "
        "sequence.glb.",
    )
    p.add_argument(
        "head", help="template pack folder, reconstruction folder, or reference:male|female"
    )
    p.add_argument("--sex", choices=["female", "male"], required=True)
    p.add_argument(
        "--from",
        dest="from_age",
        type=float,
        required=True,
        metavar="AGE",
        help="the head's age now (years)",
    )
    target = p.add_mutually_exclusive_group(required=True)
    target.add_argument("--to", dest="to_age", type=float, metavar="AGE", help="target age (years)")
    target.add_argument(
        "--ages",
        default=None,
        metavar="A,B,C",
        help="several target ages (one pack each, and one growth sequence)",
    )
    p.add_argument(
        "--norms",
        default="facial_norms",
        help="norms table id or a CSV file in the same format (default facial_norms)",
    )
    p.add_argument(
        "--ethnicity",
        default=None,
        help="population of the norms (default European; see data_tables/growth)",
    )
    p.add_argument(
        "--arc-increase",
        type=float,
        default=0.0,
        metavar="FRACTION",
        help="young-child arc-length increase, 0-0.10 (Kähler §8.5.5; fuller cheeks)",
    )
    p.add_argument(
        "--allow-sex-mismatch",
        action="store_true",
        help="age the head with the norms of --sex even when the head is of the other sex "
        "(refused otherwise; the report then says so)",
    )
    p.add_argument("--out", type=Path, required=True, metavar="DIR", help="output folder")
    p.add_argument("--no-pdf", action="store_true", help="skip report.pdf (and its pictures)")
    add_force_option(p, folder=True)
    p.set_defaults(handler=run)


def run(args: argparse.Namespace) -> JobOutcome:
    """The aged heads with their report; the growth figures as values."""
    from workbench.cli.animate_cmd import load_head
    from workbench.model.evidence import file_sha256
    from workbench.pipelines.age import age_to_folder_with_report
    from workbench.pipelines.batch.figures import age_figures
    from workbench.services.age.job import check_head_sex, parse_ages

    ages = parse_ages(args.ages) if args.ages is not None else (float(args.to_age),)
    allow = bool(getattr(args, "allow_sex_mismatch", False))
    kind, _, named = str(args.head).partition(":")
    if kind == "reference":  # refused before the head is loaded (or built: ~10 s)
        check_head_sex(named, args.sex, args.head, allow_mismatch=allow)
    if not args.no_pdf:
        # the pictures need VTK: loaded now, before the long work, with Ctrl-C held back
        # while it loads (importing workbench.render does it; without VTK: no pictures)
        import workbench.render  # noqa: F401
    head, _frame, paths = load_head(args.head)
    mismatch = check_head_sex(head, args.sex, args.head, allow_mismatch=allow)
    if mismatch:
        print(f"  warning: {mismatch}", file=sys.stderr)
    inputs = []
    for root in paths:
        pack = root if (root / "template.json").is_file() else root / "head"
        inputs.append(
            {"role": "head", "file": str(root), "sha256": file_sha256(pack / "template.json")}
        )
    if args.norms.lower().endswith(".csv"):
        norms_path = Path(args.norms)
        if not norms_path.is_file():
            raise InputError(norms_path, "does not exist (a norms CSV was expected)")
        inputs.append({"role": "norms", "file": norms_path.name, "sha256": file_sha256(norms_path)})
    results, files = age_to_folder_with_report(
        head,
        args.out,
        sex=args.sex,
        from_age=args.from_age,
        ages=ages,
        norms=args.norms,
        ethnicity=args.ethnicity,
        arc_increase=args.arc_increase,
        inputs=inputs,
        input_paths=[*paths, *([Path(args.norms)] if args.norms.lower().endswith(".csv") else [])],
        force=args.force,
        progress=lambda m: print(f"  {m}"),
        report=not args.no_pdf,
        note=lambda m: print(f"  note: {m}"),
        warnings=[mismatch] if mismatch else [],
    )
    for path in files:
        if path.parent == Path(args.out).resolve() or path.suffix in (".json", ".pdf", ".glb"):
            print(f"wrote {path}")
    for r in results:
        for w in r.warnings:
            print(f"  note ({r.to_age:g} y): {w}")
    summary = {
        "out": str(Path(args.out).resolve()),
        "ages": [
            {
                "to_age": r.to_age,
                "hard_residual_mm": r.figures["hard_residual_mm"],
                "z_change_max": r.figures["z_change_max"],
                "head_circumference_mm": r.figures["head_circumference_mm"],
                "unconstrained": r.figures["unconstrained"],
                "seconds": r.figures["seconds"],
            }
            for r in results
        ],
    }
    write_json(summary, None)
    return JobOutcome(0, age_figures(summary))
