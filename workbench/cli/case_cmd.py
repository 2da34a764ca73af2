"""``workbench case new|info|evidence``: case files from the command line."""

from __future__ import annotations

import argparse
from pathlib import Path

from workbench.cli.common import add_force_option, add_units_options, output_path, write_json
from workbench.io.case_file import evidence_bytes, save_case
from workbench.io.samples import resolve_input
from workbench.services.case.case_setup import describe_case, start_case_from_skull


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "case",
        help="create and inspect case files (.fcase)",
        description="Case files keep the original evidence byte for byte with "
        "its SHA-256, the working data, and an append-only audit log.",
    )
    csub = p.add_subparsers(dest="case_command", metavar="ACTION", required=True)

    new = csub.add_parser("new", help="start a case from a skull mesh")
    new.add_argument("skull", help="skull mesh file or sample:NAME")
    add_units_options(new)
    new.add_argument(
        "--landmarks",
        type=Path,
        default=None,
        help="skull landmarks to import (.mrk.json .fcsv .pp .csv)",
    )
    new.add_argument("--examiner", default="")
    new.add_argument("--out", type=Path, required=True, help="case file to write (.fcase)")
    add_force_option(new)
    new.set_defaults(handler=run_new)

    info = csub.add_parser(
        "info",
        help="summary, evidence check and audit log (JSON)",
        description="audit_chain.status is 'verified (N records)', "
        "'NOT VERIFIED: ...' naming the first bad record, or "
        "'audit log predates the hash chain (not verifiable)'.  "
        "audit_chain.content.status says whether case.json is as the workbench "
        "last wrote it: 'verified (...)', 'NOT VERIFIED: case.json was changed "
        "outside the workbench after ...', or 'content not sealed (written by an "
        "older version)'.  A case file that is damaged, padded (a member over its "
        "size or compression-ratio limit), encrypted or lists a member twice is "
        "refused, with or without --allow-tampered.",
    )
    info.add_argument("case", type=Path)
    info.add_argument(
        "--allow-tampered",
        action="store_true",
        help="report a case whose evidence no longer matches its hashes, whose "
        "audit log was edited or whose case.json was changed outside the "
        "workbench, instead of refusing it",
    )
    info.set_defaults(handler=run_info)

    ev = csub.add_parser("evidence", help="extract an original evidence file")
    ev.add_argument("case", type=Path)
    ev.add_argument("name", help="evidence file name (see 'case info')")
    ev.add_argument("--out", type=Path, required=True)
    add_force_option(ev)
    ev.set_defaults(handler=run_evidence)


def run_new(args: argparse.Namespace) -> int:
    from workbench.io.outputs import check_output_file

    skull = resolve_input(args.skull)
    check_output_file(args.out, [skull, args.landmarks], args.force)  # before the work
    opened = start_case_from_skull(
        skull,
        units=args.units,
        scale=args.scale,
        examiner=args.examiner,
        landmarks_path=args.landmarks,
    )
    with output_path(args.out, args, skull, args.landmarks) as out:
        save_case(opened.case, out, opened.stack)
    for note in opened.notes:
        print(f"note: {note}")
    print(f"wrote {args.out} (case {opened.case.meta.case_id})")
    return 0


def run_info(args: argparse.Namespace) -> int:
    write_json(describe_case(args.case, allow_tampered=args.allow_tampered), None)
    return 0


def run_evidence(args: argparse.Namespace) -> int:
    from workbench.io.outputs import check_output_file

    check_output_file(args.out, [args.case], args.force)
    data = evidence_bytes(args.case, args.name)
    with output_path(args.out, args, args.case) as out:
        tmp = out.with_name(f".{out.name}.part")
        tmp.write_bytes(data)
        tmp.replace(out)
    print(f"wrote {args.out} ({len(data)} bytes, verified against the recorded SHA-256)")
    return 0
