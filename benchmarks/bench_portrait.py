"""Portraits (issue 34 item 4): three views at print size, off-screen, against the 10 s budget.

What it does: loads a head (the male reference head, or a template pack /
reconstruction folder given as HEAD), then renders the portrait the way
``workbench portrait`` does, ``--runs`` times each in colour and in clay:
front, three-quarter and profile at ``--size`` px (2000 by default) in one
off-screen plotter (:func:`workbench.render.portrait.make_portrait`).  It
prints, per version:

* the seconds for the three views (median and max over the runs), against
  the budget of 10 s and as a share of it;
* the parts of it: preparing the parts (refinement, painted eyes, ambient
  occlusion ray-cast), the first view (with the plotter's set-up and the
  shaders' compilation) and each further view;
* the seconds to write the six files (PNG and TIFF at 300 dpi).

With ``--hair STYLE`` (and ``--beard``, ``--brows``) the head wears those
pieces of the library (an appearance with them): the first run includes
growing them (strands over the skin, cached after), the others reuse them;
the growing time is printed apart.  With ``--keep DIR`` the last run's
pictures are written into DIR/colour and DIR/clay.  The head is loaded
before the clock starts.

Run::

    python benchmarks/bench_portrait.py [HEAD] [--size 2000] [--runs 3] [--keep DIR]
        [--hair short --brows soft_arch --beard short]

Figures, not assertions (2 shared cores: other work on the machine shows
in the maximum).
"""

from __future__ import annotations

import argparse
import statistics
import sys
import tempfile
import time
from pathlib import Path

BUDGET_S = 10.0


def _load(spec: str):
    from workbench.cli.animate_cmd import load_head

    return load_head(spec)[0]


def _one(head, size: int, colour: bool, keep: Path | None, look=None) -> dict[str, float]:
    from workbench.render.portrait import make_portrait, write_portrait

    t0 = time.perf_counter()
    portrait = make_portrait(head, size=size, colour=colour, appearance=look)
    total = time.perf_counter() - t0
    figures = {"total": total, **portrait.seconds}
    with tempfile.TemporaryDirectory() as tmp:
        out = keep if keep is not None else Path(tmp)
        t1 = time.perf_counter()
        write_portrait(portrait, out)
        figures["write"] = time.perf_counter() - t1
    return figures


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("head", nargs="?", default="reference:male")
    parser.add_argument("--size", type=int, default=2000)
    parser.add_argument("--runs", type=int, default=3)
    parser.add_argument("--keep", type=Path, default=None)
    for kind in ("hair", "brows", "beard", "moustache"):
        parser.add_argument(f"--{kind}", default=None)
    args = parser.parse_args(argv)

    t = time.perf_counter()
    head = _load(args.head)
    print(f"head {args.head}: {head.template_id} (loaded in {time.perf_counter() - t:.1f} s)")
    look = None
    chosen = {k: getattr(args, k) for k in ("hair", "brows", "beard", "moustache")}
    chosen = {k: v for k, v in chosen.items() if v}
    if chosen:
        from workbench.model.appearance import Appearance
        from workbench.render.portrait import portrait_head
        from workbench.services.grooming import hair_meshes

        look = Appearance(grooming=chosen)
        t = time.perf_counter()
        pieces = hair_meshes(portrait_head(head)[0], look)  # grown once, then cached
        grow = time.perf_counter() - t
        triangles = sum(p.mesh.n_faces for p in pieces)
        print(
            f"wearing {', '.join(f'{k} {v}' for k, v in chosen.items())}: grown in {grow:.2f} s, "
            f"{triangles} ribbon triangles (not in the figures below)"
        )
    print(f"3 views at {args.size} x {args.size} px, {args.runs} runs each; budget {BUDGET_S:g} s")
    for colour in (True, False):
        name = "colour" if colour else "clay"
        runs = []
        for i in range(args.runs):
            keep = None
            if args.keep is not None and i == args.runs - 1:
                keep = args.keep / name
                keep.mkdir(parents=True, exist_ok=True)
            runs.append(_one(head, args.size, colour, keep, look))
        total = [r["total"] for r in runs]
        med = statistics.median(total)
        print(
            f"{name:6s}: {med:5.2f} s median, {max(total):5.2f} s max for 3 views "
            f"({med / BUDGET_S:.0%} of the {BUDGET_S:g} s budget); "
            f"prepare {statistics.median(r['prepare'] for r in runs):.2f} s, "
            f"front {statistics.median(r['front'] for r in runs):.2f} s, "
            f"three-quarter {statistics.median(r['three_quarter'] for r in runs):.2f} s, "
            f"profile {statistics.median(r['profile'] for r in runs):.2f} s; "
            f"writing PNG + TIFF {statistics.median(r['write'] for r in runs):.2f} s"
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())
