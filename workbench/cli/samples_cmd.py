"""``workbench samples list|fetch``: public sample data.

``list`` shows each sample's licence, the credit line it must carry (if
any, e.g. the NLM Visible Human credit and frozen-copy note) and which of
its files can only come from a local mirror (no public URL).
"""

from __future__ import annotations

import argparse

from workbench.io.samples import cache_dir, fetch, registry


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "samples",
        help="list or download public sample data",
        description="Public sample data (downloaded on demand, verified by SHA-256). "
        "Any command that reads a file also accepts sample:NAME.",
    )
    ssub = p.add_subparsers(dest="samples_command", metavar="ACTION", required=True)
    ls = ssub.add_parser("list", help="registered samples")
    ls.set_defaults(handler=run_list)
    f = ssub.add_parser("fetch", help="download a sample (if needed) and print its path")
    f.add_argument("name")
    f.set_defaults(handler=run_fetch)


_SHOWN_FILES = 3


def run_list(args: argparse.Namespace) -> int:
    print(f"cache: {cache_dir()}")
    samples = registry()
    width = max([12, *(len(name) for name in samples)])
    indent = " " * (width + 7)  # under the description: name, kind (5), two spaces
    for name, sample in samples.items():
        print(f"{name:{width}s} {sample.kind:5s} {sample.description}")
        print(f"{indent}licence: {sample.licence}")
        if sample.credit:
            print(f"{indent}credit: {sample.credit}")
        mirror_only = sample.mirror_only_files
        if mirror_only:
            names = ", ".join(f.path for f in mirror_only[:_SHOWN_FILES])
            if len(mirror_only) > _SHOWN_FILES:
                names += f" (+{len(mirror_only) - _SHOWN_FILES} more)"
            line = (
                f"{indent}mirror only (no public URL; from WORKBENCH_SAMPLE_MIRRORS or the "
                f"cache): {names}"
            )
            if sample.derived_from:
                line += f"; download {sample.derived_from} for the original data"
            print(line)
    return 0


def run_fetch(args: argparse.Namespace) -> int:
    print(fetch(args.name, progress=True))
    return 0
