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

``--unseen`` runs only the fully automatic cases of ``VALIDATION.md``'s
"unseen inputs": each CT's bone made outside the project (VTK's flying edges
at 300 HU, or 1150 for headsq, the largest piece, nothing else), no
orientation, no landmarks, scored beside the uniform 6 mm offset, with the
identity test (the pack built from the CT's own skin and bone, also from the
bone alone).

``--features`` runs the same unseen cases with the soft-tissue truth
landmarks of ``tests/data/soft_tissue_truth`` (the true skin at the level they
were placed on): per feature (pronasale, alar and mouth width, lip heights,
canthi) the error of the face, of the same fit without guides and of every
guide rule alone, in ``features.csv`` and ``results.md``.

Each case runs with the built-in reference head at the table's means
(normal build); with ``--builds`` the two Visible Human cadavers also run at
heavier builds (mean + k SD, k in :data:`BUILD_GRID`), and each is scored at
the k that does best on the *other* cadaver (leave-one-subject-out: the
cases used to pick the build are not the ones it is judged on; the cut VHP
female skull takes the female's k, so the male's).  Both cadavers are
heavier than the table's mean subject (puffy post mortem), which a
practitioner would see from the body; headsq stays at the means.  With
``--library`` also
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


#: builds tried with ``--builds`` (mean + k SD of the table)
BUILD_GRID = (1.0, 1.5, 2.0, 2.5, 3.0)
#: the subjects of ``--builds``: cases with their manifest row (build column set per k)
HEAVY = ("vhp_female", "vhp_male")


def _rows(manifest_path: Path) -> list[str]:
    return manifest_path.read_text(encoding="utf-8").splitlines()[1:]


def _with_build(row: str, case_id: str, k: float) -> str:
    import csv
    import io

    cells = next(csv.reader([row]))
    cols = HEADER.strip().split(",")
    cells[cols.index("id")] = case_id
    cells[cols.index("build")] = f"{k:g}"
    buf = io.StringIO()
    csv.writer(buf, lineterminator="").writerow(cells)
    return buf.getvalue()


def _results(path: Path) -> dict[tuple[str, str], dict[str, str]]:
    import csv

    with path.open(encoding="utf-8") as f:
        return {(r["case"], r["method"]): r for r in csv.DictReader(f)}


def builds(base_manifest: Path, out: Path) -> str:
    """Leave-one-subject-out build choice for the cadavers; a Markdown table."""
    from workbench.cli.main import main as workbench

    by_id = {r.split(",", 1)[0]: r for r in _rows(base_manifest)}
    grid_rows = [
        _with_build(by_id[s], f"{s}@k{k:g}", k) for s in HEAVY if s in by_id for k in BUILD_GRID
    ]
    grid_manifest = out.parent / f"{out.name}_grid_manifest.csv"
    grid_manifest.write_text(HEADER + "\n".join(grid_rows) + "\n", encoding="utf-8")
    workbench(["validate", str(grid_manifest), "--out", str(out / "grid"), "--force"])
    grid = _results(out / "grid" / "results.csv")

    def pct(case: str, method: str = "reconstruction") -> float:
        r = grid.get((case, method))
        return float(r["pct_within_2_5mm"]) if r and r["status"] == "ok" else float("nan")

    def mean_abs(case: str) -> float:
        r = grid.get((case, "reconstruction"))
        return float(r["mean_abs_mm"]) if r and r["status"] == "ok" else float("inf")

    # the build is a thickness offset: the k with the smallest mean |d| on the other cadaver
    # (the % within 2.5 mm is flat at its top and peaked: a poor criterion to transfer)
    chosen: dict[str, float] = {}
    by_pct: dict[str, float] = {}
    for s in HEAVY:
        others = [o for o in HEAVY if o != s and o in by_id]
        if s not in by_id or not others:
            continue
        cost = [sum(mean_abs(f"{o}@k{k:g}") for o in others) for k in BUILD_GRID]
        chosen[s] = BUILD_GRID[min(range(len(cost)), key=lambda i: cost[i])]
        gain = [sum(pct(f"{o}@k{k:g}") for o in others) for k in BUILD_GRID]
        by_pct[s] = BUILD_GRID[max(range(len(gain)), key=lambda i: gain[i])]
    judged = [(s, f"{s}@k{chosen[s]:g}", grid) for s in chosen]
    if "vhp_female_cut" in by_id and "vhp_female" in chosen:
        k = chosen["vhp_female"]
        cut_manifest = out.parent / f"{out.name}_cut_manifest.csv"
        cut_id = f"vhp_female_cut@k{k:g}"
        cut_manifest.write_text(
            HEADER + _with_build(by_id["vhp_female_cut"], cut_id, k) + "\n", encoding="utf-8"
        )
        workbench(["validate", str(cut_manifest), "--out", str(out / "cut"), "--force"])
        judged.append(("vhp_female_cut", cut_id, _results(out / "cut" / "results.csv")))
    lines = [
        "# Cadaver builds, chosen leave-one-subject-out",
        "",
        "Grid (% within 2.5 mm / mean |d| mm, reconstruction; k = table mean + k SD):",
        "",
        "| subject | " + " | ".join(f"k = {k:g}" for k in BUILD_GRID) + " |",
        "|---|" + "---|" * len(BUILD_GRID),
    ]
    for s in HEAVY:
        if s in by_id:
            lines.append(
                f"| {s} | "
                + " | ".join(
                    f"{pct(f'{s}@k{k:g}'):.1f} / {mean_abs(f'{s}@k{k:g}'):.2f}" for k in BUILD_GRID
                )
                + " |"
            )
    lines += [
        "",
        "Judged at the k with the smallest mean |d| on the other cadaver "
        "(% within 2.5 mm / mean |d| mm):",
        "",
        "| case | k (chosen on) | reconstruction | uniform 6 mm offset | gain (points) |",
        "|---|---|---|---|---|",
    ]
    for case, cid, res in judged:
        rec, off = res.get((cid, "reconstruction")), res.get((cid, "uniform_6mm_offset"))
        if not rec or not off or rec["status"] != "ok":
            lines.append(f"| {case} | – | failed | | |")
            continue
        subject = "vhp_female" if case == "vhp_female_cut" else case
        on = ", ".join(o for o in HEAVY if o != subject)
        gain = float(rec["pct_within_2_5mm"]) - float(off["pct_within_2_5mm"])
        lines.append(
            f"| {case} | {chosen[subject]:g} ({on}) | {float(rec['pct_within_2_5mm']):.1f} % / "
            f"{float(rec['mean_abs_mm']):.2f} | {float(off['pct_within_2_5mm']):.1f} % / "
            f"{float(off['mean_abs_mm']):.2f} | {gain:+.1f} |"
        )
    lines += [
        "",
        "Chosen by the largest % within 2.5 mm instead: "
        + ", ".join(f"{s} k = {k:g}" for s, k in by_pct.items())
        + ".",
        "",
        "Courtesy of the U.S. National Library of Medicine (Visible Human data).",
    ]
    text = "\n".join(lines) + "\n"
    (out / "builds.md").write_text(text, encoding="utf-8")
    return text


#: the CTs of ``--unseen``: (id, sample, bone level in the volume's values, mask, anterior,
#: superior, left (for the metric only), sex, subject)
UNSEEN = (
    ("headsq_plain", "headsq", 1150.0, "none", "0,-1,0", "0,0,-1", "1,0,0", "male", "headsq"),
    ("vhp_female_plain", "vhp_female", 300.0, "clip_patch:10", "0,1,0", "0,0,1", "-1,0,0",
     "female", "vhp_female"),
    ("vhp_male_plain", "vhp_male", 300.0, "behind_clip:3", "0,1,0", "0,0,1", "-1,0,0",
     "male", "vhp_male"),
)  # fmt: skip


def plain_bone(volume_path: Path, iso: float, out: Path) -> Path:
    """The bone as 3D Slicer or InVesalius export it: VTK's flying edges at ``iso`` on the
    volume as it is (no cropping, smoothing or decimation), the largest connected piece,
    in the volume's physical frame (mm)."""
    import numpy as np
    import pyvista as pv
    import vtk

    from workbench.core.isosurface import face_component_labels
    from workbench.core.mesh import Mesh
    from workbench.io.meshes import write_mesh
    from workbench.io.volumes import read_volume

    if out.is_file():
        return out
    vol = read_volume(volume_path)
    image = pv.ImageData(dimensions=vol.shape_ijk)
    image.point_data["v"] = np.asarray(vol.data, np.float32).ravel(order="C")
    edges = vtk.vtkFlyingEdges3D()
    edges.SetInputData(image)
    edges.SetValue(0, iso)
    edges.ComputeNormalsOff()
    edges.Update()
    surface = pv.wrap(edges.GetOutput()).triangulate().clean()
    ijk = np.asarray(surface.points, np.float64)
    points = ijk @ vol.affine[:3, :3].T + vol.affine[:3, 3]
    faces = np.asarray(surface.faces).reshape(-1, 4)[:, 1:]
    labels = face_component_labels(faces, len(points))
    faces = faces[labels == np.argmax(np.bincount(labels))]
    used, faces = np.unique(faces, return_inverse=True)
    out.parent.mkdir(parents=True, exist_ok=True)
    return write_mesh(out, Mesh(points[used], faces.reshape(-1, 3)).outward())


def unseen(out: Path) -> int:
    """Fully automatic from bones made outside the project (``VALIDATION.md``, unseen
    inputs): no orientation, no landmarks; the identity test from automatic registration."""
    from workbench.cli.main import main as workbench
    from workbench.io.samples import fetch

    rows = []
    for cid, sample, iso, mask, ant, sup, left, sex, who in UNSEEN:
        path = fetch(sample)
        volume = path / "quarter.nhdr" if path.is_dir() else path
        bone = plain_bone(volume, iso, out.parent / "plain_bones" / f"{cid}.ply")
        rows.append(
            f'{cid},{bone},sample:{sample},mm,{mask},"{ant}","{sup}","{left}",auto,{sex},normal,'
            f",,{who}"
        )
    path = out.parent / f"{out.name}_manifest.csv"
    path.write_text(HEADER + "\n".join(rows) + "\n", encoding="utf-8")
    code = workbench(["validate", str(path), "--identity", "--out", str(out), "--force"])
    print((out / "results.md").read_text(encoding="utf-8"))
    print(build_model_summary(out))
    return code


#: the build a practitioner would be told for each subject when the class is chosen
#: leave-one-subject-out: the class that does best (mean |d|) on the *other* subjects of the
#: same kind (the two cadavers choose for each other; headsq, the only living subject, has
#: no other and keeps the default, average)
LOSO_PEERS = {"vhp_female": ("vhp_male",), "vhp_male": ("vhp_female",)}


def build_model_summary(out: Path) -> str:
    """The issue-31 figures of a validate run (``results.csv``, ``bands.csv``): per case the
    three faces beside the offset, the closest of the three, the class chosen leave-one-
    subject-out, and the band's coverage (written to ``build_model.md``)."""
    import csv

    with (out / "results.csv").open(encoding="utf-8") as fh:
        res = {(r["case"], r["method"]): r for r in csv.DictReader(fh)}
    bands: dict[tuple[str, str], dict[str, str]] = {}
    if (out / "bands.csv").is_file():
        with (out / "bands.csv").open(encoding="utf-8") as fh:
            bands = {(r["case"], r["band"]): r for r in csv.DictReader(fh) if r["region"] == "all"}
    cases = sorted({c for c, m in res if m == "reconstruction"})

    def fig(case: str, build: str) -> tuple[float, float]:
        method = "reconstruction" if build == "average" else f"reconstruction_{build}"
        r = res[(case, method)]
        return float(r["pct_within_2_5mm"]), float(r["mean_abs_mm"])

    def subject(case: str) -> str:
        return case.removesuffix("_plain").removesuffix("_auto")

    names = ("slender", "average", "heavy")
    lines = [
        "# Three builds, the band, and the build class chosen leave-one-subject-out",
        "",
        "% within 2.5 mm / mean |d| mm of each face; the uniform 6 mm offset; the gain of the "
        "closest of the three and of the class chosen on the other subject(s) (points of % "
        "within 2.5 mm); band: % of the scored true skin inside the 95 % band (median "
        "half-width mm), build unknown and build given as the chosen class.",
        "",
        "| case | slender | average | heavy | offset | closest (gain) | class chosen on | "
        "class (gain) | band, unknown | band, class |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    for case in cases:
        if (case, "reconstruction_heavy") not in res:
            continue
        f = {b: fig(case, b) for b in names}
        off = res[(case, "uniform_6mm_offset")]
        off_pct = float(off["pct_within_2_5mm"])
        best = max(names, key=lambda b: f[b][0])
        peers = [c for c in cases if subject(c) in LOSO_PEERS.get(subject(case), ())]
        if peers:
            chosen = min(names, key=lambda b: sum(fig(p, b)[1] for p in peers))
            on = ", ".join(peers)
        else:
            chosen, on = "average", "– (default)"
        band_u = bands.get((case, "unknown"), {})
        band_c = bands.get((case, chosen), {})

        def band(b: dict[str, str]) -> str:
            if not b:
                return "–"
            return f"{100 * float(b['coverage']):.1f} ({float(b['half_width_median_mm']):.1f})"

        lines.append(
            f"| {case} | "
            + " | ".join(f"{f[b][0]:.1f} / {f[b][1]:.2f}" for b in names)
            + f" | {off_pct:.1f} / {float(off['mean_abs_mm']):.2f}"
            + f" | {best} ({f[best][0] - off_pct:+.1f}) | {on} | {chosen} "
            f"({f[chosen][0] - off_pct:+.1f}) | {band(band_u)} | {band(band_c)} |"
        )
    text = "\n".join(lines) + "\n"
    (out / "build_model.md").write_text(text, encoding="utf-8")
    return text


#: the soft-tissue truth landmarks (tests/data/soft_tissue_truth) and the skin level they
#: were placed on (the true skin must be that surface)
TRUTH_LANDMARKS = ROOT / "tests" / "data" / "soft_tissue_truth"
TRUTH_SKIN_ISO = {"headsq": 500.0, "vhp_female": -400.0, "vhp_male": -400.0}


def features(out: Path) -> int:
    """The nose, mouth and eye guides against the true skins' landmarks: the unseen
    cases (plain bones, no orientation) with ``truth_landmarks``, so ``validate`` adds
    the fit without guides and every rule's own error (``features.csv``)."""
    from workbench.cli.main import main as workbench
    from workbench.io.samples import fetch

    rows = []
    for cid, sample, iso, mask, ant, sup, left, sex, who in UNSEEN:
        path = fetch(sample)
        volume = path / "quarter.nhdr" if path.is_dir() else path
        bone = plain_bone(volume, iso, out.parent / "plain_bones" / f"{cid}.ply")
        marks = TRUTH_LANDMARKS / f"{sample}.mrk.json"
        rows.append(
            f'{cid},{bone},sample:{sample},mm,{mask},"{ant}","{sup}","{left}",auto,{sex},normal,'
            f",{TRUTH_SKIN_ISO[sample]:g},{who},{marks}"
        )
    path = out.parent / f"{out.name}_manifest.csv"
    path.write_text(
        HEADER.strip() + ",truth_landmarks\n" + "\n".join(rows) + "\n", encoding="utf-8"
    )
    code = workbench(["validate", str(path), "--no-pictures", "--out", str(out), "--force"])
    print((out / "results.md").read_text(encoding="utf-8"))
    return code


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--quick", action="store_true", help="headsq and VHP female only")
    parser.add_argument(
        "--library",
        action="store_true",
        help="also leave-one-out over the other subjects' references, and the identity test",
    )
    parser.add_argument(
        "--builds",
        action="store_true",
        help="also the cadavers at heavier builds, k chosen leave-one-subject-out",
    )
    parser.add_argument(
        "--unseen",
        action="store_true",
        help="only the fully automatic runs on plain marching-cubes bones (VTK flying edges, "
        "largest piece, as other programs export them) with the identity test",
    )
    parser.add_argument(
        "--features",
        action="store_true",
        help="the unseen cases scored per feature (nose, mouth, eyes) against the true "
        "skins' landmarks, beside no guides and every rule alone",
    )
    parser.add_argument("--out", type=Path, default=ROOT / "benchmarks" / "results" / "validation")
    args = parser.parse_args()
    if args.unseen:
        return unseen(args.out.with_name(args.out.name + "_unseen"))
    if args.features:
        return features(args.out.with_name(args.out.name + "_features"))
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
    if args.builds and not args.quick:
        print(builds(m, args.out))
    return code


if __name__ == "__main__":
    sys.exit(main())
