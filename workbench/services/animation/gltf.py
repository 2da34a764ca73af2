"""An animated head as glTF: every palette expression as a morph target of the skin.

:func:`expression_targets` settles each expression from rest (a fresh
:class:`~workbench.services.animation.animator.Animator` per expression, so no
expression inherits another's residue) and returns the skin and the jaw
parts in the Frankfort head frame (mm).  :func:`export_head_glb` writes them
with :func:`workbench.io.gltf_export.write_glb` **in the head's own frame**,
the frame of its PLY files (a reconstruction's ``head/`` pack and
``face.ply``: the skull file's frame, mirrored when that file is; the
reference heads: the head frame), in metres: a glTF vertex × 1000 is the
PLY's vertex in mm.  A glTF frame with weight 1 on one target is the skin
``workbench animate --expression NAME --out FILE.ply`` writes.

Every part has a material (:func:`workbench.core.appearance.head_looks`):
the skin a skin-tone preset with the lips apart, or the fit's colour atlas
when one is given (:func:`workbench.io.skin_colour_export.read_skin_texture`
reads it from a ``fit-scan`` pack); the eyes an iris texture; teeth, bone and
tongue their presets.  The colours are artistic defaults, not evidence.

Hair, brows, beard and moustache (an ``appearance`` with styles chosen,
:mod:`workbench.services.grooming`; artistic additions, not evidence) are
nodes of their own, grown on the rest skin and again on every settled
expression's skin, so each has the skin's morph targets: the brows rise with
the brows, the beard opens with the jaw.  Every strand is kept
(:data:`HAIR_STRIDE`); the hair's targets are sparse (displacements under
:data:`HAIR_MIN_MM` written as 0), see :mod:`workbench.io.gltf_export`.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from os import PathLike
from pathlib import Path

import numpy as np

from workbench.core.appearance import (
    DEFAULT_IRIS,
    DEFAULT_SKIN_TONE,
    Look,
    SkinTexture,
    head_looks,
)
from workbench.core.errors import InputError
from workbench.core.mesh import Mesh
from workbench.io.arkit_table import read_arkit_table
from workbench.io.gltf_export import Keyframes, Shading, write_glb
from workbench.model.appearance import Appearance
from workbench.model.template import TemplateHead
from workbench.services.animation.animator import EXPRESSIONS, Animator, Expression
from workbench.services.registration.jaw import JAW_PARTS, axis_rotation

__all__ = [
    "HAIR_MIN_MM",
    "HAIR_STRIDE",
    "ExpressionTargets",
    "arkit_needed",
    "arkit_recipes",
    "export_head_glb",
    "expression_targets",
    "ramp_keyframes",
    "settle_expressions",
    "settle_poses",
]


#: the animation's glTF keeps every so many strands of the scalp hair (brows and beards
#: all); 1, every strand: long hair, thick brows, full beard and moustache on the male
#: reference head make a 42 MB file with 8 expression targets, 78 MB with all 28
HAIR_STRIDE = 1
#: hair displacements (mm) below this are written as 0 in the glTF's sparse morph targets
HAIR_MIN_MM = 0.01


@dataclass
class ExpressionTargets:
    """Rest meshes and per-expression positions in the Frankfort head frame (mm).

    The ``stored_*`` fields hold the same in the head's own frame (the frame
    its files are in, with their triangle winding), which the ``.glb`` uses.
    """

    rest: dict[str, Mesh]  #: every part of the head at rest ("skin", "eyes", "mandible" ...)
    skin: dict[str, np.ndarray] = field(default_factory=dict)  #: name -> (n, 3) skin positions
    #: part -> name -> positions, for jaw parts of expressions that move the jaw
    parts: dict[str, dict[str, np.ndarray]] = field(default_factory=dict)
    steps: dict[str, int] = field(default_factory=dict)
    stored_rest: dict[str, Mesh] = field(default_factory=dict)
    stored_skin: dict[str, np.ndarray] = field(default_factory=dict)
    stored_parts: dict[str, dict[str, np.ndarray]] = field(default_factory=dict)


def _check_names(names: Iterable[str] | None) -> list[str]:
    chosen = list(EXPRESSIONS) if names is None else list(names)
    unknown = [n for n in chosen if n not in EXPRESSIONS]
    if unknown:
        raise InputError(
            ", ".join(unknown), "is not an expression", "valid names: " + ", ".join(EXPRESSIONS)
        )
    if not chosen:
        raise InputError("expressions", "none given", "name at least one expression")
    return list(dict.fromkeys(chosen))


def settle_expressions(
    head: TemplateHead,
    names: Iterable[str] | None = None,
    progress: Callable[[str], None] | None = None,
) -> ExpressionTargets:
    """Settle each expression from rest; skin and moved jaw parts in the head frame (mm)."""
    chosen = _check_names(names)
    return settle_poses(head, {name: EXPRESSIONS[name] for name in chosen}, progress)


def settle_poses(
    head: TemplateHead,
    poses: Mapping[str, Expression],
    progress: Callable[[str], None] | None = None,
) -> ExpressionTargets:
    """Settle each pose (an :class:`Expression`, e.g. a track's key or viseme) from rest.

    Skin and moved jaw parts in the head frame (mm), keyed by the poses' names.
    """
    if not poses:
        raise InputError("expressions", "none given", "name at least one expression")
    out: ExpressionTargets | None = None
    for name, pose in poses.items():
        anim = Animator(head)
        if out is None:
            out = ExpressionTargets(rest=dict(anim.head.meshes), stored_rest=dict(head.meshes))
        anim.set_expression(pose)
        out.steps[name] = anim.settle()
        out.skin[name] = anim.skin_in_head_frame()
        out.stored_skin[name] = anim.skin().vertices  # as `animate --out FILE.ply` writes it
        if anim.jaw_deg != 0.0 or anim.protrusion_mm != 0.0:
            # Animator.meshes() is in the head's own frame: the same jaw pose in the head frame
            point, direction = anim.head.tmj_axis
            m = axis_rotation(point, direction, np.deg2rad(anim.jaw_deg))
            m[:3, 3] += np.array([0.0, 0.0, anim.protrusion_mm])
            for part in JAW_PARTS:
                if part in out.rest:
                    v = out.rest[part].vertices
                    out.parts.setdefault(part, {})[name] = v @ m[:3, :3].T + m[:3, 3]
            posed = anim.meshes()  # the same jaw pose in the head's own frame
            for part in JAW_PARTS:
                if part in out.stored_rest:
                    out.stored_parts.setdefault(part, {})[name] = posed[part].vertices
        if progress is not None:
            progress(name)
    assert out is not None
    return out


def expression_targets(
    head: TemplateHead, names: Iterable[str] | None = None
) -> dict[str, np.ndarray]:
    """``{expression: (n, 3) settled skin positions}`` in the head frame (mm), from rest.

    ``names``: expressions of :data:`~workbench.services.animation.animator.EXPRESSIONS`
    (default: all of them, the emotions and the FACS action units).
    """
    return settle_expressions(head, names).skin


def export_head_glb(
    head: TemplateHead,
    path: str | PathLike[str],
    names: Iterable[str] | None = None,
    keyframes: Keyframes | None = None,
    *,
    weights: Mapping[str, float] | None = None,
    names_arkit: Mapping[str, Mapping[str, float]] | None = None,
    progress: Callable[[str], None] | None = None,
    poses: Mapping[str, Expression] | None = None,
    frame: str = "",
    skin_tone: str = DEFAULT_SKIN_TONE,
    iris: str = DEFAULT_IRIS,
    skin_texture: SkinTexture | None = None,
    eyes: str = "texture",
    looks: Mapping[str, Look] | None = None,
    appearance: Appearance | None = None,
    hair_stride: int = HAIR_STRIDE,
) -> tuple[Path, ExpressionTargets, float]:
    """Write the head as ``.glb`` with the expressions as morph targets.

    Returns ``(path, the settled targets, seconds spent settling)``.  The rest
    skin and the parts are the head's meshes in its own frame (that of its
    PLY files; ``frame`` describes it for the file's ``extras``), in metres;
    parts that follow the jaw get morph targets for the expressions that
    open or push the jaw.  ``names_arkit`` (see :func:`arkit_recipes`) adds
    targets that are weighted sums of the settled ones; the expressions they
    use must be among ``names``.  ``poses`` adds targets that are not palette
    expressions (a track's key poses and visemes, named by the caller), after
    ``names``; ``names=[]`` with ``poses`` exports only those.

    ``skin_tone`` (:data:`~workbench.core.appearance.SKIN_TONES`), ``iris``
    (:data:`~workbench.core.appearance.IRIS_COLOURS`), ``skin_texture`` (the
    fit's atlas, made for this skin) and ``eyes`` (``"texture"`` or
    ``"vertex"``: finer globes with per-vertex colours) choose the materials;
    ``looks`` replaces those of the parts it names (a case's chosen colours:
    :func:`workbench.services.appearance.appearance_looks`).

    ``appearance``: the hair, brows, beard and moustache it chose (and their
    colours) become nodes ``hair``, ``brows``, ``beard``, ``moustache`` with a
    morph target per target of the skin (grown on each settled skin), the
    scalp hair every ``hair_stride`` strand.  Its skin colours are not applied
    here: pass them in ``looks``.
    """
    try:  # refuse a bad colour name before the expressions are settled
        looks = head_looks(
            head.meshes,
            getattr(head, "eye_centres", None),  # (stand-ins for a head may lack these)
            regions=getattr(head, "regions", None),
            tone=skin_tone,
            iris=iris,
            skin_texture=skin_texture,
            eyes=eyes,
        ) | dict(looks or {})
    except ValueError as exc:
        raise InputError("appearance", str(exc)) from None
    # grown before the expressions are settled: a head without the landmarks fails at once
    hair = _hair_parts(head, appearance, hair_stride)
    t0 = time.perf_counter()
    given = None if names is None else list(names)
    chosen = [] if given is not None and not given and poses else _check_names(given)
    clash = [n for n in (poses or {}) if n in chosen]
    if clash:
        raise InputError(", ".join(clash), "is both an expression target and a pose target")
    settled = settle_poses(
        head, {**{n: EXPRESSIONS[n] for n in chosen}, **dict(poses or {})}, progress
    )
    seconds = time.perf_counter() - t0
    rest = settled.stored_rest
    extra = {k: m for k, m in rest.items() if k != "skin"}
    node_targets = dict(settled.stored_parts)
    shading: dict[str, Shading] = {}
    if hair:
        looks = dict(looks)
        for kind, (mesh, look, normals) in hair.items():
            extra[kind] = mesh
            looks[kind] = look
            shading[kind] = Shading(
                normals, double_sided=True, tinted=True, min_displacement_mm=HAIR_MIN_MM
            )
        node_targets.update(_hair_targets(head, appearance, settled.stored_skin, hair_stride))
    out = write_glb(
        path,
        rest["skin"],
        settled.stored_skin,
        extra_nodes=extra,
        node_targets=node_targets,
        shading=shading,
        weights=weights,
        animation=keyframes,
        names_arkit=names_arkit,
        frame=frame or "the head's own frame, as in its PLY files",
        looks=looks,
    )
    return out, settled, seconds


def _hair_parts(
    head: TemplateHead, appearance: Appearance | None, stride: int
) -> dict[str, tuple[Mesh, Look, np.ndarray]]:
    """``{kind: (mesh, look, shading normals)}`` of the chosen pieces on the rest skin
    (the head's own frame): a material per kind in its colour, the strands' colours
    per vertex."""
    from workbench.services.grooming import hair_look, hair_meshes

    if appearance is None:
        return {}
    return {
        piece.kind: (piece.mesh, hair_look(piece, appearance), piece.normals)
        for piece in hair_meshes(head, appearance, stride=stride)
    }


def _hair_targets(
    head: TemplateHead,
    appearance: Appearance | None,
    skins: Mapping[str, np.ndarray],
    stride: int,
) -> dict[str, dict[str, np.ndarray]]:
    """``{kind: {target: positions}}``: the pieces grown on each settled skin (float32:
    the hair has many vertices)."""
    from workbench.services.grooming import hair_meshes

    out: dict[str, dict[str, np.ndarray]] = {}
    for name, skin in skins.items():
        for piece in hair_meshes(head, appearance, skin, stride=stride):
            out.setdefault(piece.kind, {})[name] = piece.mesh.vertices.astype(np.float32)
    return out


def ramp_keyframes(
    name: str, seconds: float = 1.0, steps: int = 1
) -> Sequence[tuple[float, dict[str, float]]]:
    """Keyframes from neutral (all weights 0) to ``name`` at weight 1 over ``seconds``."""
    ts = np.linspace(0.0, seconds, steps + 1)
    return [(float(t), {name: float(t / seconds)}) for t in ts]


def arkit_recipes(path: str | PathLike[str] | None = None) -> dict[str, dict[str, float]]:
    """``{ARKit name: {expression: weight}}`` from an ARKit table (default: the built-in one).

    Every recipe target must be an expression of
    :data:`~workbench.services.animation.animator.EXPRESSIONS` (else :class:`InputError`
    naming the file, row and the valid names); an empty recipe is a shape
    with no AU basis, written as zero displacement.
    """
    recipes = read_arkit_table(path, valid=EXPRESSIONS)
    clash = [n for n in recipes if n in EXPRESSIONS]
    if clash:
        raise InputError(
            path or "ARKit table",
            f"{', '.join(clash)} is an expression name, not a new target name",
            "give the ARKit shapes names of their own",
        )
    return recipes


def arkit_needed(recipes: Mapping[str, Mapping[str, float]]) -> list[str]:
    """The expressions the recipes use, in first-use order (to add to the settled set)."""
    return list(dict.fromkeys(t for mix in recipes.values() for t in mix))
