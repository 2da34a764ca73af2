"""Benchmark: skull → face accuracy on the real CT cases, beside the uniform 6 mm offset.

Run ``python benchmarks/bench_validation.py [--quick]`` from the repository
root with ``../shared/data`` beside the checkout (or WORKBENCH_SAMPLE_MIRRORS
set).  It writes a manifest for the real cases and runs ``workbench
validate`` on it into ``benchmarks/results/validation/`` (not committed):
``results.csv``, ``results.md``, ``results.pdf`` and a folder per case.

Cases (the metric and the masks of ``VALIDATION.md``):

* ``headsq``: VTK headsq CT (3.2 mm voxels, vault cut, open mouth), bone
  iso 1150, skin 500;
* ``vhp_female``: Visible Human female, 1 mm, bone 300 HU, skin −400 HU, the
  nose tip clipped by the field of view masked (``clip_patch:10``);
* ``vhp_male``: Visible Human male, 1 mm, face clipped flat in front: only
  the skin at least 3 mm behind the clipping plane is scored
  (``behind_clip:3``);
* ``vhp_female_cut``: the VHP female bone without mandible, with a frontal
  defect and the vault cut open (``benchmarks/cases/cut_skull.py``), scored
  against the same true skin; same subject as ``vhp_female``;
* ``*_auto``: headsq and VHP female again, oriented from the bone alone
  (no axes given to the reconstruction).

Each case runs with the built-in reference head; with ``--library`` also
leave-one-out over reference heads built from the *other* subjects' skin
and bone (their per-vertex median) and the identity test (the subject's
own reference, tissue model ``reference``).

Courtesy of the U.S. National Library of Medicine (Visible Human data); the
copy used may not be the most current NLM data.
"""

from __future__ import annotations

import argparse
import os
import shutil
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
SHARED = ROOT.parent / "shared" / "data"
os.environ.setdefault("WORKBENCH_SAMPLE_MIRRORS", str(SHARED))

HEADER = (
    "id,skull,truth,units,mask,anterior,superior,left,orient,sex,build,bone_iso,skin_iso,subject\n"
)


def manifest(out: Path, quick: bool) -> Path:
    from benchmarks.cases.cut_skull import make_cut_skull
    from workbench.io.samples import fetch

    vhpf = fetch("vhp_female")
    rows = [
        'headsq,sample:headsq,sample:headsq,mm,none,"0,-1,0","0,0,-1","1,0,0",hint,male,'
        "normal,1150,500,headsq",
        'vhp_female,sample:vhp_female,sample:vhp_female,mm,clip_patch:10,"0,1,0","0,0,1",'
        '"-1,0,0",hint,female,normal,300,-400,vhp_female',
    ]
    if not quick:
        cut = make_cut_skull(vhpf, out.parent / "cases" / "vhp_female_cut")
        cut_dir = Path(cut.get("out_dir", out.parent / "cases" / "vhp_female_cut"))
        rows += [
            'vhp_male,sample:vhp_male,sample:vhp_male,mm,behind_clip:3,"0,1,0","0,0,1",'
            '"-1,0,0",hint,male,normal,300,-400,vhp_male',
            f"vhp_female_cut,{cut_dir / 'cut_skull.ply'},{cut_dir / 'skin.ply'},mm,clip_patch:10,"
            '"0,1,0","0,0,1","-1,0,0",hint,female,normal,,,vhp_female',
            'headsq_auto,sample:headsq,sample:headsq,mm,none,"0,-1,0","0,0,-1","1,0,0",auto,male,'
            "normal,1150,500,headsq",
            'vhp_female_auto,sample:vhp_female,sample:vhp_female,mm,clip_patch:10,"0,1,0",'
            '"0,0,1","-1,0,0",auto,female,normal,300,-400,vhp_female',
        ]
    # beside the results, not in them: validate refuses an output folder holding an input
    out.parent.mkdir(parents=True, exist_ok=True)
    path = out.parent / f"{out.name}_manifest.csv"
    path.write_text(HEADER + "\n".join(rows) + "\n", encoding="utf-8")
    return path


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--quick", action="store_true", help="headsq and VHP female only")
    parser.add_argument(
        "--library",
        action="store_true",
        help="also leave-one-out over the other subjects' references, and the identity test",
    )
    parser.add_argument("--out", type=Path, default=ROOT / "benchmarks" / "results" / "validation")
    args = parser.parse_args()
    from workbench.cli.main import main as workbench

    m = manifest(args.out, args.quick)
    # --force keeps the previous run as OUT.1 (its surfaces and reference packs are reused);
    # the run before that is dropped so the results folder does not grow without end
    previous = args.out.with_name(args.out.name + ".1")
    if previous.is_dir() and args.out.is_dir():
        shutil.rmtree(previous)
    argv = ["validate", str(m), "--out", str(args.out), "--force"]
    if args.library:
        argv += ["--leave-one-out", "--identity"]
    code = workbench(argv)
    print((args.out / "results.md").read_text(encoding="utf-8"))
    return code


if __name__ == "__main__":
    sys.exit(main())
