#!/usr/bin/env python
"""Robustness corpus benchmark (issue 28): the automatic registration on bone meshes made
the way other programs make them.

Builds the corpus when missing (``benchmarks/results/corpus/meshes/``, git-ignored; meshes
derived from the CTs are never committed), registers every variant with no hints, no seeds
and the male reference, and scores it against its truth (the medians of the base CT's
hinted registrations at the variants' bone levels, carried through the same transforms).  Units mm and degrees; the landmarks
are compared in each file's own frame.  Run from the repository root::

    WORKBENCH_SAMPLE_MIRRORS=../shared/data .venv/bin/python benchmarks/bench_robustness.py \
        --label baseline

Writes ``benchmarks/results/corpus/run_<label>/`` (``results.csv``, ``summary.json``,
``summary.md``) and prints the Markdown summary.  Resumable: variants already scored with
the same code hash are skipped unless ``--force``.  See :mod:`benchmarks.corpus`.

Visible Human data: Courtesy of the U.S. National Library of Medicine.
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
BASES = ("headsq", "vhp_female", "vhp_male")


def export_revision(code: str) -> Path:
    """A folder holding a ``workbench`` package: ``code`` itself when it is one, else the
    git revision ``code`` of this checkout exported (``git archive``: workbench/ and
    data_tables/) into ``benchmarks/results/corpus/code/<commit>/`` (kept for reuse)."""
    folder = Path(code)
    if (folder / "workbench" / "__init__.py").is_file():
        return folder
    sha = subprocess.run(
        ["git", "-C", str(ROOT), "rev-parse", "--verify", f"{code}^{{commit}}"],
        check=True,
        capture_output=True,
        text=True,
    ).stdout.strip()
    folder = ROOT / "benchmarks" / "results" / "corpus" / "code" / sha[:12]
    if not (folder / "workbench" / "__init__.py").is_file():
        folder.mkdir(parents=True, exist_ok=True)
        archive = subprocess.run(
            ["git", "-C", str(ROOT), "archive", sha, "workbench", "data_tables"],
            check=True,
            capture_output=True,
        ).stdout
        subprocess.run(["tar", "-x", "-C", str(folder)], input=archive, check=True)
    return folder


def use_code(code: str) -> Path:
    """Make ``workbench`` import from ``code`` (:func:`export_revision`), so a run can
    measure the committed code while someone edits the working tree.  Must run before
    anything imports it."""
    folder = export_revision(code)
    if "workbench" in sys.modules:
        raise RuntimeError("workbench was imported before --code could take effect")
    sys.path.insert(0, str(folder.resolve()))
    return folder


def stratified(specs: list, n: int) -> list:
    """About ``n`` specs, each base in proportion, evenly spread over its (shuffled) indices
    so every dimension keeps most of its values; the "cut" group is sampled alike."""
    total = len(specs)
    out = []
    for name in BASES:
        for group in ("plain", "cut"):
            mine = [s for s in specs if s.base == name and s.group == group]
            if not mine:
                continue
            k = max(1, round(n * len(mine) / total))
            picks = sorted({int(round(i * len(mine) / k)) for i in range(k)})
            out += [mine[i] for i in picks if i < len(mine)]
    return out


def select(specs: list, args: argparse.Namespace) -> list:
    from benchmarks.corpus.variants import generate_specs, quick_ids

    if args.only:
        specs = [s for s in specs if s.base == args.only]
    if args.quick:
        wanted = set(quick_ids(generate_specs()))
        specs = [s for s in specs if s.id in wanted]
    if args.ids:
        wanted = [i.strip() for i in args.ids.split(",") if i.strip()]
        specs = [s for s in specs if any(s.id == w or s.id.startswith(w) for w in wanted)]
    if args.sample:
        specs = stratified(specs, args.sample)
    if args.limit:
        specs = specs[: args.limit]
    return specs


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--label", default="dev", help="run name: results in run_<label>/")
    parser.add_argument("--limit", type=int, default=0, help="first N selected variants")
    parser.add_argument("--only", choices=BASES, help="one base CT")
    parser.add_argument("--ids", default="", help="comma-separated variant ids (or prefixes)")
    parser.add_argument("--quick", action="store_true", help="the fixed 12-variant subset")
    parser.add_argument("--sample", type=int, default=0, help="a stratified subset of ~N")
    parser.add_argument("--jobs", type=int, default=1, help="worker processes (default 1)")
    parser.add_argument("--force", action="store_true", help="re-run scored variants")
    parser.add_argument("--rebuild", action="store_true", help="rebuild the variant meshes")
    parser.add_argument("--build-only", action="store_true", help="build the corpus and stop")
    parser.add_argument(
        "--control",
        action="store_true",
        help="also register each mesh with the orientation hint: the automatic result is then "
        "judged against the hinted one on the same surface too",
    )
    parser.add_argument(
        "--code",
        default="",
        help="measure this workbench: a git revision (e.g. HEAD) or a folder holding one "
        "(default: the one this interpreter imports, i.e. the working tree)",
    )
    args = parser.parse_args(argv)
    if args.code:
        print(f"workbench from {use_code(args.code)}")
    if str(ROOT) not in sys.path:
        sys.path.append(str(ROOT))  # benchmarks.*; after --code, so it cannot shadow it

    from benchmarks.corpus.evaluate import evaluate, markdown
    from benchmarks.corpus.variants import build_corpus, generate_specs

    specs = select(generate_specs(), args)
    if not specs:
        parser.error("no variant selected")
    t0 = time.perf_counter()
    print(f"building {len(specs)} variants (cached) ...")
    entries = build_corpus(specs, force=args.rebuild)
    print(f"corpus ready in {time.perf_counter() - t0:.0f} s")
    if args.build_only:
        return 0
    summary = evaluate(entries, args.label, jobs=args.jobs, force=args.force, control=args.control)
    print(markdown(summary, f"Robustness corpus: run '{args.label}'"))
    print(f"total {time.perf_counter() - t0:.0f} s")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
