"""``workbench samples list|fetch``: public sample data."""

from __future__ import annotations

import argparse

from workbench.io.samples import cache_dir, fetch, registry


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("samples", help="list or download public sample data",
                       description="Public sample data (downloaded on demand, verified by SHA-256). "
                                   "Any command that reads a file also accepts sample:NAME.")
    ssub = p.add_subparsers(dest="samples_command", metavar="ACTION", required=True)
    ls = ssub.add_parser("list", help="registered samples")
    ls.set_defaults(handler=run_list)
    f = ssub.add_parser("fetch", help="download a sample (if needed) and print its path")
    f.add_argument("name")
    f.set_defaults(handler=run_fetch)


def run_list(args: argparse.Namespace) -> int:
    print(f"cache: {cache_dir()}")
    for name, sample in registry().items():
        print(f"{name:12s} {sample.kind:5s} {sample.description}")
        print(f"{'':12s}       licence: {sample.licence}")
    return 0


def run_fetch(args: argparse.Namespace) -> int:
    print(fetch(args.name, progress=True))
    return 0
