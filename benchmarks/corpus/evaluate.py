"""Run the automatic registration on every corpus variant and score it against its truth.

Units mm, degrees.  Each variant goes the way ``workbench reconstruct SKULL``
goes up to the registration, with no orientation hint, no seed landmarks and
the male reference head (a user may not know the sex):
``read_mesh(path, units=...)`` → ``working_skull`` → ``register_skull``.
The raw outputs (found landmarks in the **file frame**, the jaw pose, the
outcome) are stored per variant, keyed by a hash of the code a variant runs
through (:func:`benchmarks.corpus.common.scored_code_hash`), so a run resumes
and scores can be recomputed against a newer truth without registering again.

Scores of one variant (:func:`score`):

* orientation right: all six landmarks (g, n, po_l, po_r, or_l, or_r) within
  :data:`LANDMARK_TOLERANCE_MM` of the truth — the medians of the base's hinted
  registrations at every bone level the variants use (one per level, see
  :func:`benchmarks.corpus.truth.compute_truth`), with the reference head this
  run uses (the base's own-sex reference's is
  reported beside it: two references put a landmark a few mm apart, which is
  not a matter of orientation); for a mirrored file (whose
  left/right cannot be known from its shape) the swapped labelling counts too,
  and how many came out swapped is reported; the same again for the landmarks a
  user receives (g snapped to its feature, the other midline landmarks onto the
  midline: ``landmarks_snapped``);
* mandible found (``reg.part("mandible").present``) when the variant has one,
  and a false mandible when it has none;
* jaw opening error (found − truth, degrees), within
  :data:`OPENING_TOLERANCE_DEG` when the orientation is right;
* outcome: "refused" when a :class:`~workbench.core.errors.WorkbenchError` is
  raised, else ``reg.figures["self_check"]["outcome"]`` ("confident" when the
  registration has no self-check); "error" for any other exception (a crash);
* "wrong face with exit 0": orientation wrong and the outcome "confident" (a
  "check" exits with status 3 and a refusal with 2, see ``workbench.cli.main``;
  a crash is counted apart).
"""

from __future__ import annotations

import time
import traceback
from collections.abc import Callable, Iterable
from pathlib import Path
from typing import Any

import numpy as np

from benchmarks.corpus.common import (
    apply,
    code_root,
    jsonable,
    read_json,
    results_dir,
    scored_code_hash,
    write_json,
)
from benchmarks.corpus.truth import EVAL_SEX, SIX, SWAPPED
from benchmarks.corpus.variants import DIMENSIONS, corpus_dir

LANDMARK_TOLERANCE_MM = 5.0
#: a landmark error beyond this is a grossly wrong orientation (not a near miss)
GROSS_MM = 20.0
OPENING_TOLERANCE_DEG = 3.0
TARGETS = {
    "variants": 200,
    "orientation_right_pct": 99.0,
    "mandible_found_pct": 98.0,
    "wrong_not_refused": 0,
    "refused_pct_max": 1.0,
}
#: dimensions the summary breaks the figures down by
BREAKDOWN = ("base", "group", *DIMENSIONS, "shift")


def shift_bin(translation) -> str:
    """The file's shift (mm) in three bins, a dimension of its own in the breakdown."""
    d = float(np.linalg.norm(translation))
    return "0-150 mm" if d < 150 else ("150-350 mm" if d < 350 else "350-500 mm")


# ---------------------------------------------------------------- one variant
def run_variant(
    entry: dict[str, Any], root: Path | None = None, control: bool = False
) -> dict[str, Any]:
    """The automatic registration of one variant; raw outputs (file frame, mm).

    With ``control`` the same mesh is also registered with the base's orientation hint
    carried through the file's transform (``control_landmarks``): how far the automatic
    result lies from the hinted one *on the same surface* separates a wrong orientation
    from landmarks that move with the surface (another iso, smoothing, decimation).
    """
    from benchmarks.corpus.truth import condylar_axis_h, jaw_pose, snapped_input
    from workbench.core.errors import WorkbenchError
    from workbench.io.meshes import read_mesh
    from workbench.services.reconstruction.service import working_skull
    from workbench.services.registration.skull_registration import register_skull
    from workbench.services.templates.cache import reference_head

    path = corpus_dir(root) / entry["file"]
    head = reference_head(EVAL_SEX)
    out: dict[str, Any] = {"id": entry["id"], "code_hash": scored_code_hash(), "sex": EVAL_SEX}
    t0 = time.perf_counter()
    try:
        read = read_mesh(path, units=entry["units"], kind="skull")
        work, _ = working_skull(read.mesh)
        out["n_faces_file"], out["n_faces_work"] = read.mesh.n_faces, work.n_faces
        t1 = time.perf_counter()
        reg = register_skull(work, head)
        out["seconds_registration"] = time.perf_counter() - t1
    except WorkbenchError as exc:
        out.update(outcome="refused", message=str(exc), error_type=type(exc).__name__)
        out["seconds"] = time.perf_counter() - t0
        return jsonable(out, 6)
    except Exception as exc:  # noqa: BLE001 - a crash is a result to count, not to raise
        out.update(
            outcome="error",
            message=f"{type(exc).__name__}: {exc}",
            traceback=traceback.format_exc(limit=8),
        )
        out["seconds"] = time.perf_counter() - t0
        return jsonable(out, 6)
    out["seconds"] = time.perf_counter() - t0
    back = np.linalg.inv(reg.input_to_head)
    point_h, _ = condylar_axis_h(reg, head)
    pose = jaw_pose(reg, point_h)
    self_check = reg.figures.get("self_check", {}) or {}
    if control:
        from benchmarks.corpus.bases import BASES

        x = np.asarray(entry["truth"]["file_transform"], np.float64)
        r = x[:3, :3] / abs(np.linalg.det(x[:3, :3])) ** (1 / 3)
        hint = tuple(
            tuple(r @ np.asarray(h, np.float64)) for h in BASES[entry["spec"]["base"]].hint
        )
        try:
            hinted = register_skull(work, head, hint=hint)
            hb = np.linalg.inv(hinted.input_to_head)
            out["control_landmarks"] = {c: apply(hb, hinted.inferred[c]) for c in SIX}
            out["control_mirrored"] = bool(hinted.mirrored)
        except WorkbenchError as exc:
            out["control_error"] = str(exc)
    out.update(
        outcome=self_check.get("outcome", "confident"),
        self_check=self_check,
        check_measures=reg.figures.get("check_measures"),
        jaw_reported=reg.figures.get("jaw"),
        warnings=list(reg.warnings),
        landmarks={c: apply(back, reg.inferred[c]) for c in SIX},
        landmarks_snapped=snapped_input(reg, work),
        mirrored=bool(reg.mirrored),
        mandible_found=bool(reg.part("mandible").present),
        mandible_pose_fraction=reg.figures.get("mandible_pose_fraction"),
        jaw={
            "opening_deg": pose.opening_deg,
            "protrusion_mm": pose.protrusion_mm,
            "lateral_mm": pose.lateral_mm,
        },
        orientation={
            k: reg.figures.get("orientation", {}).get(k)
            for k in ("method", "cost", "handedness", "mirrored", "reference_scale")
        },
    )
    return jsonable(out, 6)


def _worker(args: tuple[dict[str, Any], str | None, bool]) -> dict[str, Any]:
    entry, root, control = args
    return run_variant(entry, Path(root) if root else None, control)


# ---------------------------------------------------------------- scoring
def _defined(p: Any) -> bool:
    return p is not None and all(v is not None for v in p)


def _max_error(found: dict, truth: dict, names: dict[str, str] | None = None) -> float:
    names = names or {c: c for c in SIX}
    return float(
        max(np.linalg.norm(np.asarray(found[names[c]]) - np.asarray(truth[c])) for c in SIX)
    )


def score(raw: dict[str, Any], entry: dict[str, Any], base_truth: dict[str, Any]) -> dict:
    """Scores of one variant from its raw outputs and its truth (see the module docstring)."""
    truth = entry["truth"]
    spec = entry["spec"]
    row: dict[str, Any] = {
        "id": entry["id"],
        "base": spec["base"],
        "group": spec["group"],
        **{d: spec[d] if d != "mirrored" else spec["mirror_axis"] >= 0 for d in DIMENSIONS},
        "shift": shift_bin(spec["translation"]),
        "outcome": raw.get("outcome"),
        "seconds": raw.get("seconds"),
        "mirrored_file": bool(truth["mirrored_file"]),
        "has_mandible": bool(truth["mandible_present"]),
        "warnings": raw.get("warnings", []),
        "message": raw.get("message", ""),
    }
    ran = raw.get("outcome") not in ("refused", "error")
    row["ran"] = ran
    if not ran:
        row.update(
            orientation_ok=False,
            swapped=False,
            max_error_mm=None,
            max_error_own_sex_reference_mm=None,
            mandible_found=False,
            opening_found_deg=None,
            opening_error_deg=None,
            opening_ok=False,
            wrong_not_refused=False,
        )
        return row
    found = raw["landmarks"]
    # the truth is the base's hinted registration *as the code under test makes it*
    # (``base_truth`` is recomputed when the registration code changes; the truths stored
    # with the variants are those of the code that built the corpus), carried through the
    # variant's file transform: with the reference this run uses (two references put a
    # landmark a few mm apart, which is not orientation), the base's own-sex one beside it
    x = np.asarray(truth["file_transform"], np.float64)
    own = {c: apply(x, np.asarray(base_truth["landmarks"][c])) for c in SIX}
    other = base_truth.get("other_reference", {}).get(EVAL_SEX)
    if other is not None:
        primary = {c: apply(x, np.asarray(other["landmarks"][c])) for c in SIX}
    else:
        primary = own
    direct = _max_error(found, primary)
    swapped = _max_error(found, primary, SWAPPED)
    ok_direct = direct <= LANDMARK_TOLERANCE_MM
    ok_swapped = swapped <= LANDMARK_TOLERANCE_MM
    orientation_ok = ok_direct or (row["mirrored_file"] and ok_swapped)
    # the same for the landmarks a user receives (g snapped to its feature), when both the
    # run and the truth have them
    snapped = raw.get("landmarks_snapped")
    source = other if other is not None else base_truth
    if snapped is not None and "landmarks_snapped" in source:
        # a landmark the registration marks absent (too little bone seen there) is not in
        # the user's file; the pose used its inferred place, which stands in for it here
        snapped = {c: p if _defined(p) else found[c] for c, p in snapped.items()}
        truth_s = {
            c: apply(x, np.asarray(p if _defined(p) else source["landmarks"][c]))
            for c, p in source["landmarks_snapped"].items()
            if c in SIX
        }
        e_s = _max_error(snapped, truth_s)
        if row["mirrored_file"]:
            e_s = min(e_s, _max_error(snapped, truth_s, SWAPPED))
        row["max_error_snapped_mm"] = e_s
    control = raw.get("control_landmarks")
    if control is not None:
        swap = bool(raw.get("control_mirrored")) != bool(raw.get("mirrored"))
        row["max_error_vs_hinted_same_mesh_mm"] = _max_error(
            found, control, SWAPPED if swap else None
        )
    e_direct, e_swapped = _max_error(found, own), _max_error(found, own, SWAPPED)
    row["max_error_own_sex_reference_mm"] = (
        min(e_direct, e_swapped) if row["mirrored_file"] else e_direct
    )
    row.update(
        orientation_ok=orientation_ok,
        swapped=bool(not ok_direct and ok_swapped),
        max_error_mm=min(direct, swapped) if row["mirrored_file"] else direct,
        max_error_direct_mm=direct,
        mandible_found=bool(raw["mandible_found"]),
        opening_found_deg=(raw.get("jaw_reported") or {}).get("opening_deg")
        or raw["jaw"]["opening_deg"],
    )
    err = None
    opening_truth = None
    # the opening the registration reports (its jaw pose about the condylar axis) when the
    # run and the truth both have it, else the Procrustes measure of the registered parts
    base_jaw = base_truth["jaw_by_reference"][EVAL_SEX]
    reported = (raw.get("jaw_reported") or {}).get("opening_deg")
    use_reported = reported is not None and base_jaw.get("reported_opening_deg") is not None
    found_opening = reported if use_reported else raw["jaw"]["opening_deg"]
    if row["has_mandible"]:
        # the base's opening (as the code under test measures it) plus the one applied
        base_opening = base_jaw["reported_opening_deg" if use_reported else "opening_deg"]
        opening_truth = base_opening + float(truth["applied"]["opening_deg"])
    if row["has_mandible"] and row["mandible_found"] and opening_truth is not None:
        err = found_opening - opening_truth
    row["opening_truth_deg"] = opening_truth
    row["opening_measure"] = "reported" if use_reported else "procrustes"
    row["opening_error_deg"] = err
    row["opening_ok"] = bool(
        err is not None and orientation_ok and abs(err) <= OPENING_TOLERANCE_DEG
    )
    expected = (truth.get("jaw_expected") or {}).get(EVAL_SEX)
    if expected and err is not None:
        flip = -1.0 if row["swapped"] or (raw["mirrored"] != row["mirrored_file"]) else 1.0
        row["protrusion_error_mm"] = raw["jaw"]["protrusion_mm"] - expected["protrusion_mm"]
        row["lateral_error_mm"] = flip * raw["jaw"]["lateral_mm"] - expected["lateral_mm"]
    # a "check" leaves with exit status 3 and its reason first: not a plain success
    row["wrong_not_refused"] = bool(not orientation_ok and raw["outcome"] == "confident")
    return row


# ---------------------------------------------------------------- aggregation
def _pct(k: int, n: int) -> float | None:
    return round(100.0 * k / n, 1) if n else None


def _within(rows: list[dict[str, Any]], key: str) -> float | None:
    """Percentage of the ``rows`` that have ``key`` whose error there is within tolerance."""
    have = [r[key] for r in rows if r.get(key) is not None]
    return _pct(sum(e <= LANDMARK_TOLERANCE_MM for e in have), len(have))


def stats(rows: list[dict[str, Any]]) -> dict[str, Any]:
    """Counts and percentages over ``rows`` (see the module docstring)."""
    n = len(rows)
    ran = [r for r in rows if r["ran"]]
    has = [r for r in rows if r["has_mandible"]]
    missing = [r for r in ran if not r["has_mandible"]]
    found = [r for r in has if r["mandible_found"]]
    ok = sum(r["orientation_ok"] for r in rows)
    mirrored = [r for r in ran if r["mirrored_file"]]
    errs = [abs(r["opening_error_deg"]) for r in found if r.get("opening_error_deg") is not None]
    times = [r["seconds"] for r in rows if r.get("seconds") is not None]
    max_err = [r["max_error_mm"] for r in ran if r.get("max_error_mm") is not None]
    own_ref_ok = sum(
        1
        for r in ran
        if r.get("max_error_own_sex_reference_mm") is not None
        and r["max_error_own_sex_reference_mm"] <= LANDMARK_TOLERANCE_MM
    )
    return {
        "n": n,
        "orientation_right": ok,
        "orientation_right_pct": _pct(ok, n),
        "orientation_right_vs_own_sex_reference_pct": _pct(own_ref_ok, n),
        "orientation_right_vs_hinted_same_mesh_pct": _within(
            ran, "max_error_vs_hinted_same_mesh_mm"
        ),
        "orientation_right_snapped_pct": _within(ran, "max_error_snapped_mm"),
        "with_mandible": len(has),
        "mandible_found": len(found),
        "mandible_found_pct": _pct(len(found), len(has)),
        "opening_within_3deg": sum(r["opening_ok"] for r in has),
        "opening_within_3deg_pct": _pct(sum(r["opening_ok"] for r in has), len(has)),
        "opening_abs_error_median_deg": round(float(np.median(errs)), 2) if errs else None,
        "false_mandible_when_missing": sum(r["mandible_found"] for r in missing),
        "without_mandible": len([r for r in rows if not r["has_mandible"]]),
        "wrong_not_refused": sum(r["wrong_not_refused"] for r in rows),
        "wrong_not_refused_pct": _pct(sum(r["wrong_not_refused"] for r in rows), n),
        "refused": sum(r["outcome"] == "refused" for r in rows),
        "refused_pct": _pct(sum(r["outcome"] == "refused" for r in rows), n),
        "check": sum(r["outcome"] == "check" for r in rows),
        "errors": sum(r["outcome"] == "error" for r in rows),
        "mirrored_files": len(mirrored),
        "swapped_labels": sum(r["swapped"] for r in mirrored),
        "gross_wrong": sum(e > GROSS_MM for e in max_err),
        "near_miss": sum(LANDMARK_TOLERANCE_MM < e <= GROSS_MM for e in max_err),
        "max_error_median_mm": round(float(np.median(max_err)), 2) if max_err else None,
        "seconds_median": round(float(np.median(times)), 1) if times else None,
        "seconds_max": round(float(np.max(times)), 1) if times else None,
    }


def aggregate(rows: list[dict[str, Any]]) -> dict[str, Any]:
    """Overall figures, per base and per value of every dimension."""
    out: dict[str, Any] = {"overall": stats(rows), "by": {}}
    for dim in BREAKDOWN:
        values = sorted({str(r[dim]) for r in rows})
        out["by"][dim] = {v: stats([r for r in rows if str(r[dim]) == v]) for v in values}
    o = out["overall"]
    out["targets"] = {
        "at least 200 variants": o["n"] >= TARGETS["variants"],
        "orientation right >= 99 %": (o["orientation_right_pct"] or 0)
        >= TARGETS["orientation_right_pct"],
        "mandible found >= 98 % (of those with one)": (o["mandible_found_pct"] or 0)
        >= TARGETS["mandible_found_pct"],
        "no wrong face with exit 0": o["wrong_not_refused"] == 0,
        "refusals <= 1 %": (o["refused_pct"] or 0) <= TARGETS["refused_pct_max"],
    }
    return out


_COLUMNS = (
    ("n", "n"),
    ("orientation right %", "orientation_right_pct"),
    ("(landmarks as delivered, g snapped) %", "orientation_right_snapped_pct"),
    ("(vs own-sex-reference truth) %", "orientation_right_vs_own_sex_reference_pct"),
    ("vs hinted, same mesh %", "orientation_right_vs_hinted_same_mesh_pct"),
    ("mandible found %", "mandible_found_pct"),
    ("opening ≤3° %", "opening_within_3deg_pct"),
    ("median |opening err| °", "opening_abs_error_median_deg"),
    ("wrong, exit 0", "wrong_not_refused"),
    (f"of which >{GROSS_MM:g} mm", "gross_wrong"),
    ("refused", "refused"),
    ("check", "check"),
    ("crash", "errors"),
    ("false mandible", "false_mandible_when_missing"),
    ("swapped (mirrored)", "swapped_labels"),
    ("median max err mm", "max_error_median_mm"),
    ("median s", "seconds_median"),
    ("max s", "seconds_max"),
)


def _cell(v: Any) -> str:
    return "–" if v is None else str(v)


def markdown(summary: dict[str, Any], title: str) -> str:
    """The summary as Markdown tables."""
    head = "| | " + " | ".join(c for c, _ in _COLUMNS) + " |"
    rule = "|---" * (len(_COLUMNS) + 1) + "|"

    def line(name: str, s: dict[str, Any]) -> str:
        return f"| {name} | " + " | ".join(_cell(s[k]) for _, k in _COLUMNS) + " |"

    lines = [f"# {title}", ""]
    meta = summary.get("meta", {})
    if meta:
        lines += [
            f"Code {meta.get('code_root')} (hash {meta.get('code_hash')}), truth registration hash "
            f"{meta.get('truth_registration_hash')}, reference head '{EVAL_SEX}' for every "
            f"variant, no hints, no seeds.  {meta.get('credit', '')}",
            "",
        ]
    lines += ["## Targets", ""]
    for name, ok in summary["targets"].items():
        lines.append(f"- {'PASS' if ok else 'FAIL'}: {name}")
    lines += ["", "## Overall", "", head, rule, line("all", summary["overall"]), ""]
    for dim, values in summary["by"].items():
        lines += [f"## By {dim}", "", head, rule]
        lines += [line(v, s) for v, s in values.items()]
        lines.append("")
    lines += [
        "Orientation right: g, n, po_l, po_r, or_l, or_r all within "
        f"{LANDMARK_TOLERANCE_MM:g} mm of the truth (mirrored files: either labelling). "
        "Opening ≤3°: of the variants with a mandible. 'wrong, exit 0': orientation wrong "
        f"and confident (a check exits 3, a refusal 2; crashes counted apart); '>{GROSS_MM:g} mm': the largest landmark "
        "error beyond that (a wrong pose, not a near miss).",
        "",
    ]
    return "\n".join(lines)


CSV_FIELDS = (
    "id",
    "base",
    "group",
    *DIMENSIONS,
    "shift",
    "outcome",
    "seconds",
    "orientation_ok",
    "max_error_mm",
    "max_error_direct_mm",
    "max_error_own_sex_reference_mm",
    "max_error_vs_hinted_same_mesh_mm",
    "max_error_snapped_mm",
    "mirrored_file",
    "swapped",
    "has_mandible",
    "mandible_found",
    "opening_truth_deg",
    "opening_found_deg",
    "opening_error_deg",
    "opening_ok",
    "protrusion_error_mm",
    "lateral_error_mm",
    "wrong_not_refused",
    "warnings",
    "message",
)


def write_csv(path: Path, rows: list[dict[str, Any]]) -> Path:
    import csv

    with open(path, "w", newline="", encoding="utf-8") as handle:
        writer = csv.DictWriter(handle, fieldnames=CSV_FIELDS, extrasaction="ignore")
        writer.writeheader()
        for r in rows:
            flat = dict(jsonable(r, 3))
            flat["warnings"] = " | ".join(r.get("warnings") or [])
            writer.writerow(flat)
    return path


# ---------------------------------------------------------------- a run
def evaluate(
    entries: list[dict[str, Any]],
    label: str,
    *,
    jobs: int = 1,
    force: bool = False,
    root: Path | None = None,
    say: Callable[[str], None] = print,
    control: bool = False,
) -> dict[str, Any]:
    """Register every variant (resuming), score, and write the run's files (``control``:
    also the hinted registration of each mesh, see :func:`run_variant`).

    Returns the summary (also written as ``summary.json``/``summary.md`` with
    ``results.csv`` in ``run_<label>/``).
    """
    from benchmarks.corpus.truth import load_truth

    run = results_dir(f"run_{label}", root=root)
    raw_dir = results_dir(f"run_{label}", "raw", root=root)
    code = scored_code_hash()
    todo = []
    raws: dict[str, dict[str, Any]] = {}
    for entry in entries:
        p = raw_dir / f"{entry['id']}.json"
        if not force and p.is_file():
            raw = read_json(p)
            if raw.get("code_hash") == code:
                raws[entry["id"]] = raw
                continue
        todo.append(entry)
    stale = [e["id"] for e in todo if (raw_dir / f"{e['id']}.json").is_file()]
    if stale:
        say(
            f"note: {len(stale)} variants of run '{label}' were scored with other code; they "
            "are scored again (use another --label to keep both)"
        )
    say(f"{len(entries)} variants: {len(raws)} already scored with code {code}, {len(todo)} to run")
    for i, raw in enumerate(_runs(todo, jobs, root, control)):
        write_json(raw_dir / f"{raw['id']}.json", raw)
        raws[raw["id"]] = raw
        say(
            f"  [{i + 1}/{len(todo)}] {raw['id']}: {raw.get('outcome')} in "
            f"{raw.get('seconds', 0):.1f} s"
        )
    truths = {b: load_truth(b, root) for b in {e["spec"]["base"] for e in entries}}
    rows = [score(raws[e["id"]], e, truths[e["spec"]["base"]]) for e in entries]
    summary = aggregate(rows)
    summary["meta"] = {
        "label": label,
        "code_hash": code,
        "code_root": str(code_root()),
        "truth_registration_hash": sorted({t["registration_hash"] for t in truths.values()}),
        "truth_drift_from_anchor_mm": {
            b: max(t["drift_from_anchor_mm"].values()) for b, t in truths.items()
        },
        "reference": EVAL_SEX,
        "tolerance_mm": LANDMARK_TOLERANCE_MM,
        "opening_tolerance_deg": OPENING_TOLERANCE_DEG,
        "date": time.strftime("%Y-%m-%d %H:%M:%S"),
        "credit": "Visible Human data: Courtesy of the U.S. National Library of Medicine.",
    }
    write_csv(run / "results.csv", rows)
    write_json(run / "summary.json", summary)
    (run / "summary.md").write_text(
        markdown(summary, f"Robustness corpus: run '{label}'"), encoding="utf-8"
    )
    return summary


def _runs(
    todo: list[dict[str, Any]], jobs: int, root: Path | None, control: bool = False
) -> Iterable[dict[str, Any]]:
    if jobs <= 1:
        for entry in todo:
            yield run_variant(entry, root, control)
        return
    import multiprocessing
    from concurrent.futures import ProcessPoolExecutor, as_completed

    context = multiprocessing.get_context("spawn")
    with ProcessPoolExecutor(max_workers=jobs, mp_context=context) as pool:
        futures = [pool.submit(_worker, (e, str(root) if root else None, control)) for e in todo]
        for future in as_completed(futures):
            yield future.result()
