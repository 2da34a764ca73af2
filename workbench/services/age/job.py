"""``workbench age`` as a service: age a head to one or more ages and write the results.

One call for the command line, scripts and the window's age-progression
dialog.  The output folder (written as a whole, see
:func:`workbench.io.outputs.write_folder`) holds

- ``head/`` — the aged template pack (with several ages: ``head_<age>y/``
  each), in the aged head's Frankfort frame, mm;
- ``report.json`` — every measurement (value, norm mean and SD at both ages,
  z before and after, target, residual), the head circumference, the
  solve's figures, warnings;
- ``sequence.glb`` — the source skin with one morph target per age (named
  ``age_<age>y``) and a clip running through the ages (one second per age
  step), for a growth animation; eyes, teeth and the rest as nodes of the
  source head;
- whatever ``extra(folder, results)`` adds (the CLI's ``report.pdf`` with
  pictures, which needs the render layer).
"""

from __future__ import annotations

import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import replace
from os import PathLike
from pathlib import Path
from typing import Any

from workbench.core.errors import InputError
from workbench.io.atomic import write_json_atomic
from workbench.model.template import TemplateHead
from workbench.services.age.change import AgeResult, Progress, age_head, in_frankfort_frame

#: most ages one request may ask for
MAX_AGES = 40


def parse_ages(text: str) -> tuple[float, ...]:
    """``"3,8,15"`` → (3.0, 8.0, 15.0); refuses empty, non-numeric or repeated ages."""
    items = [t.strip() for t in text.split(",") if t.strip()]
    if not items:
        raise InputError("--ages", "names no age", "e.g. --ages 3,8,15")
    ages = []
    for t in items:
        try:
            ages.append(float(t))
        except ValueError:
            raise InputError("--ages", f"'{t}' is not a number of years") from None
    if len(set(ages)) != len(ages):
        raise InputError("--ages", "names an age twice")
    if len(ages) > MAX_AGES:
        raise InputError("--ages", f"{len(ages)} ages; at most {MAX_AGES} per run")
    return tuple(ages)


def _own_sex(head: TemplateHead | str) -> str:
    """``head``'s recorded sex, or ``head`` itself when it is that sex's name."""
    return (head if isinstance(head, str) else str(head.sex or "")).lower()


def sex_mismatch(head: TemplateHead | str, sex: str) -> str | None:
    """``"a female head aged with the male norms"`` when ``sex`` is not the head's own
    (``head``'s recorded ``sex``, or that sex itself); None when it is or is not known."""
    own = _own_sex(head)
    if own not in ("female", "male") or own == sex:
        return None
    return f"a {own} head aged with the {sex} norms"


def check_head_sex(
    head: TemplateHead | str, sex: str, source: str, *, allow_mismatch: bool = False
) -> str | None:
    """Refuse norms of the other sex than the head's own (see :func:`sex_mismatch`; e.g.
    ``reference:female`` before the head is loaded).

    The z-scores are read against the norms of ``sex``; a female head measured
    against male norms starts 1-2 SD off in most facial measurements, and its
    aged face follows the other sex's growth, a result that looks like any
    other.  So a mismatch stops with a message naming both, unless
    ``allow_mismatch`` (then the returned warning goes into the report).
    ``source`` names the head (``reference:female``, a pack folder).
    """
    mismatch = sex_mismatch(head, sex)
    if mismatch is None:
        return None
    own = _own_sex(head)
    if not allow_mismatch:
        raise InputError(
            source,
            f"is a {own} head, but --sex {sex} asks for the {sex} norms",
            f"give --sex {own}, or add --allow-sex-mismatch to age the {own} head with the "
            f"{sex} norms on purpose",
        )
    return f"{mismatch} (--allow-sex-mismatch): its z-scores are read against the other sex's norms"


def age_series(
    head: TemplateHead,
    ages: Sequence[float],
    *,
    sex: str,
    from_age: float,
    norms: str = "facial_norms",
    ethnicity: str | None = None,
    arc_increase: float = 0.0,
    progress: Progress | None = None,
) -> list[AgeResult]:
    """``head`` aged from ``from_age`` to each of ``ages`` (each directly from the source)."""
    say = progress or (lambda _m: None)
    out = []
    for i, age in enumerate(ages):
        say(f"age {age:g} y ({i + 1}/{len(ages)}) ...")
        out.append(
            age_head(
                head,
                sex=sex,
                from_age=from_age,
                to_age=age,
                norms=norms,
                ethnicity=ethnicity,
                arc_increase=arc_increase,
            )
        )
    return out


def pack_name(age: float, several: bool) -> str:
    return f"head_{age:g}y" if several else "head"


def report_dict(
    head: TemplateHead, results: Sequence[AgeResult], inputs: Sequence[Mapping[str, Any]]
) -> dict[str, Any]:
    """The ``report.json`` content for ``results`` (units mm, ages in years)."""
    several = len(results) > 1
    return {
        "@schema": "age-report-v1",
        "units": "mm",
        "frame": "each head's Frankfort frame (x to the subject's left, y up, z toward the face)",
        "source": {
            "template_id": head.template_id,
            "content_hash": head.content_hash,
            "inputs": [dict(i) for i in inputs],
        },
        "method": "Kähler 2003 §8.5: measurements with norms keep their z-score "
        "(d_t = mu_t + sd_t/sd_c (d_c - mu_c)) as hard constraints, the vault's height "
        "(head-ear height, vertex over porion) too where its norms cover both ages; Table 8.2 "
        "measurements without norms and nearby landmark pairs follow the head-circumference "
        "scale; per-axis least squares (SVD, condition clamp), translation anchored at the "
        "tragia; arcs after the solve; the whole head warped (Kähler's landmark spline with a "
        "rounded kernel), source tissue depths kept; eyeballs scaled by their own growth "
        "(axial length by age) and seated in the lids",
        "growth_tables": _growth_table_citations(),
        "ages": [
            {
                "to_age": r.to_age,
                "pack": pack_name(r.to_age, several),
                "template_id": r.head.template_id,
                "figures": dict(r.figures),
                "warnings": list(r.warnings),
                "measurements": [row.to_dict() for row in r.rows],
            }
            for r in results
        ],
    }


def _growth_table_citations() -> dict[str, dict[str, str]]:
    """Citations of the growth tables beside the facial norms (eyeball growth, vault height)."""
    from workbench.services.age.growth_tables import load_eyeball_growth, load_vault_norms

    vault = load_vault_norms()
    keys = {
        vault.source_of(m, s, vault.ethnicities()[0])
        for m in vault.measurement_ids()
        for s in ("female", "male")
    }
    return {
        "eyeball_axial_length": dict(load_eyeball_growth().citations),
        "vault_norms": {k: vault.citation(k) for k in sorted(keys)},
    }


def write_sequence_glb(path: Path, head: TemplateHead, results: Sequence[AgeResult]) -> Path:
    """The source skin with one morph target per age and a clip through them (one s per age)."""
    from workbench.core.appearance import head_looks
    from workbench.io.gltf_export import write_glb

    # each aged head is settled in its own Frankfort frame; the source head is in its own,
    # so the skins share axes and origin (between the porions) and morph directly
    targets = {f"age_{r.to_age:g}y": r.head.skin.vertices for r in results}
    order = sorted(results, key=lambda r: r.to_age)
    frames: list[tuple[float, dict[str, float]]] = [(0.0, {})]
    for i, r in enumerate(order):
        frames.append((float(i + 1), {f"age_{r.to_age:g}y": 1.0}))
    parts = {
        name: head.meshes[name]
        for name in ("eyes", "upper_teeth", "lower_teeth", "tongue")
        if head.meshes[name].n_vertices
    }
    node_targets = {
        name: {f"age_{r.to_age:g}y": r.head.meshes[name].vertices for r in results}
        for name in parts
    }
    return write_glb(
        path,
        head.skin,
        targets,
        extra_nodes=parts,
        node_targets=node_targets,
        animation=frames,
        clip_name="growth",
        # skin, lips, painted eyes and teeth (artistic defaults: workbench.core.appearance)
        looks=head_looks(head.meshes, head.eye_centres, regions=head.regions),
    )


def age_to_folder(
    head: TemplateHead,
    out: str | PathLike[str],
    *,
    sex: str,
    from_age: float,
    ages: Sequence[float],
    norms: str = "facial_norms",
    ethnicity: str | None = None,
    arc_increase: float = 0.0,
    inputs: Sequence[Mapping[str, Any]] = (),
    input_paths: Sequence[str | PathLike[str]] = (),
    force: bool = False,
    progress: Progress | None = None,
    extra: Callable[[Path, TemplateHead, list[AgeResult]], list[Path]] | None = None,
    warnings: Sequence[str] = (),
) -> tuple[list[AgeResult], list[Path]]:
    """Age ``head`` to ``ages`` and write packs, ``report.json`` and ``sequence.glb`` to ``out``.

    ``out`` must not hold an input; an existing folder is replaced only with
    ``force`` (kept as ``out.1``) and a failure leaves it as it was.
    ``warnings`` (e.g. from :func:`check_head_sex`) are added to every age's.
    """
    from workbench.io.outputs import check_output_folder, write_folder
    from workbench.io.template_pack import export_template

    check_output_folder(out, list(input_paths), force)
    t0 = time.perf_counter()
    results = age_series(
        head,
        ages,
        sex=sex,
        from_age=from_age,
        norms=norms,
        ethnicity=ethnicity,
        arc_increase=arc_increase,
        progress=progress,
    )
    results = [
        replace(
            r,
            warnings=(*warnings, *r.warnings),
            head=replace(
                r.head,
                template_id=f"{head.template_id}/age/{from_age:g}-{r.to_age:g}",
                provenance={
                    **dict(head.provenance),
                    "age_change": {
                        "from_age": from_age,
                        "to_age": r.to_age,
                        "sex": sex,
                        "norms": norms,
                        "ethnicity": r.figures.get("ethnicity"),
                        "figures": dict(r.figures),
                        "base_template": {
                            "template_id": head.template_id,
                            "content_hash": head.content_hash,
                        },
                    },
                },
            ),
        )
        for r in results
    ]
    seconds = time.perf_counter() - t0
    # the aged heads are in their Frankfort frames; so is the source for the morph
    # targets and the pictures (a reconstruction's head is stored in the skull file's frame)
    source = in_frankfort_frame(head)[0]

    def write(folder: Path) -> list[Path]:
        files: list[Path] = []
        several = len(results) > 1
        for r in results:
            files += export_template(r.head, folder / pack_name(r.to_age, several))
        report = report_dict(head, results, inputs)
        report["seconds"] = round(seconds, 3)
        files.append(write_json_atomic(folder / "report.json", report, indent=1))
        files.append(write_sequence_glb(folder / "sequence.glb", source, results))
        if extra is not None:
            files += extra(folder, source, results)
        return files

    return results, write_folder(out, write, force=force, inputs=list(input_paths))
