"""The reconstruction of a case held open, one step at a time (the window's tools call these).

Plain functions over the services, no Qt, no VTK: the window runs them in its
worker thread and applies their results on the GUI thread through undoable
commands; scripts and the command line call them too.  The
settings are the case's typed parts, the same ``workbench reconstruct``
records (:func:`workbench.services.reconstruction.job.run_reconstruction`):

=========== ================================================================
part        value
=========== ================================================================
dowels      :class:`~workbench.model.reconstruction_setup.DowelSettings`:
            depth table, sex, build, overrides (mm), excluded codes
orientation :class:`~workbench.model.reconstruction_setup.Orientation` of
            the skull file, or None (found from the bone)
guides      :class:`~workbench.model.reconstruction_setup.GuideList` set by
            the user, or None (computed from the skull)
=========== ================================================================

The fit is the one pipeline of the command line: :func:`fit_inputs` takes a
snapshot of the case on the GUI thread, :func:`fit_face` runs
:func:`workbench.services.reconstruction.service.run_fit` on it in the
worker; the window's export is the reconstruction pipeline's
(:func:`workbench.pipelines.reconstruct.export_fit`).

Units mm.  Landmarks, dowels and the face are returned in the **input frame**
(the skull file's frame) so they overlay the specimen; the fit itself runs in
the head frame (x to the subject's left, y up, z forward, Frankfort
Horizontal at y = 0).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from pathlib import Path

import numpy as np

from workbench.core.errors import WorkbenchError
from workbench.core.landmarks import LandmarkSet, merge_user_landmarks
from workbench.core.mesh import Mesh
from workbench.model.case import Case
from workbench.model.evidence import sha256_file
from workbench.model.reconstruction_setup import GuideList, Orientation
from workbench.model.template import TemplateHead
from workbench.services.guides.classic import Guide, guides_to_json
from workbench.services.guides.fit_guides import stored_guides
from workbench.services.landmarks.frame import input_frame
from workbench.services.reconstruction.service import (
    DowelPreview,
    FitInputs,
    FitResult,
    run_fit,
)
from workbench.services.reconstruction.service import depth_settings as _depth_settings
from workbench.services.registration.skull_registration import (
    SkullRegistration,
    mirror_from_landmarks,
    register_skull,
)
from workbench.services.templates.cache import reference_head
from workbench.services.tissue.dowels import DepthSettings, plan_dowels

__all__ = [
    "DowelPreview",
    "FitInputs",
    "FitResult",
    "depth_settings",
    "fit_face",
    "fit_inputs",
    "guide_geometry",
    "guides_state",
    "orientation",
    "preview_dowels",
    "sample_orientation",
    "suggest_landmarks",
    "user_guides",
    "view_axes",
]


def depth_settings(case: Case) -> DepthSettings:
    """The dowel planner's settings for the case's ``dowels`` part."""
    return _depth_settings(case.dowels)


def orientation(case: Case) -> tuple | None:
    """``(anterior, superior[, left])`` in file coordinates, or None (automatic)."""
    return None if case.orientation is None else case.orientation.hint


def sample_orientation(path: str | Path) -> dict[str, list[float]] | None:
    """The known anatomy directions of a public sample file, matched by SHA-256.

    ``{"anterior": [...], "superior": [...] (, "left": [...])}`` in the
    file's coordinates, or None for any other file.
    """

    from workbench.io.samples import registry

    path = Path(path)
    if not path.is_file():
        return None
    digest = sha256_file(path)[0]
    for sample in registry().values():
        main = [f for f in sample.files if f.path == sample.main]
        if sample.anatomy and main and main[0].sha256 == digest:
            return {
                k: [float(v) for v in sample.anatomy[k]]
                for k in ("anterior", "superior", "left")
                if k in sample.anatomy
            }
    return None


def anatomy_orientation(anatomy: dict[str, list[float]]) -> Orientation:
    """:func:`sample_orientation`'s directions as the case's orientation value."""
    return Orientation.from_state(anatomy)


def view_axes(case: Case) -> tuple[np.ndarray, np.ndarray] | None:
    """``(anterior, superior)`` unit vectors in the input frame for the camera.

    From the head frame of the skull landmarks when they define one, else
    from the case's orientation, else None.
    """
    try:
        to_head, _ = input_frame(case.landmarks["skull"])
    except (WorkbenchError, ValueError, KeyError, np.linalg.LinAlgError):
        orient = case.orientation
        return (
            None
            if orient is None
            else (np.array(orient.anterior, float), np.array(orient.superior, float))
        )
    back = np.linalg.inv(to_head)[:3, :3]
    a, s = back @ [0.0, 0.0, 1.0], back @ [0.0, 1.0, 0.0]
    return a / np.linalg.norm(a), s / np.linalg.norm(s)


def user_guides(case: Case) -> list[Guide] | None:
    """Guides stored in the case (edited by the user), or None (compute them)."""
    return stored_guides(case.guides)


# ------------------------------------------------------------------ suggest
def _register(
    skull: Mesh,
    current: LandmarkSet,
    head: TemplateHead | str,
    orient: tuple | None,
    progress: Callable[[str], None] | None = None,
) -> SkullRegistration:
    """The dense registration of the reference skull onto ``skull`` (input frame, mm), the
    landmarks the user placed as its seeds and their handedness as its mirror."""
    if isinstance(head, str):
        head = reference_head(head)
    placed = LandmarkSet("skull", tuple(lm for lm in current if lm.status == "placed"))
    return register_skull(
        skull,
        head,
        hint=orient,
        seeds=placed if len(placed) else None,
        mirror=mirror_from_landmarks(current),
        progress=progress,
    )


def suggest_landmarks(
    skull: Mesh,
    current: LandmarkSet,
    head: TemplateHead | str,
    orient: tuple | None,
    report: Callable[[str, float], None] | None = None,
) -> tuple[LandmarkSet, SkullRegistration]:
    """Suggest the skull landmarks not placed yet (input frame, mm), by the dense registration.

    ``head``: the reference head (or the sex of the built-in one).  Landmarks
    the user placed are seeds (and hard constraints) and stay as they are;
    landmarks the user marked absent stay absent.  Returns the new set and
    the registration (figures, warnings; reused by the fit).  The window's
    *Suggest* and ``workbench landmarks suggest`` both call this.
    """
    reg = _register(skull, current, head, orient, staged(report, SUGGEST_STAGES))
    # the one merge of the reconstruction (SetLandmarkStatus gives a person's "absent"
    # confidence 1; the registration's has 0)
    return merge_user_landmarks(reg.landmarks, current), reg


# ------------------------------------------------------------------ dowels
def _to(m: np.ndarray, p: np.ndarray) -> np.ndarray:
    return np.asarray(p, float).reshape(-1, 3) @ m[:3, :3].T + m[:3, 3]


def preview_dowels(
    skull: Mesh, landmarks: LandmarkSet, settings: DepthSettings, orient: tuple | None = None
) -> DowelPreview:
    """Plan the dowels (head frame) and map them back for display.

    The head frame comes from the landmarks' porions and orbitales, or —
    when they do not define one — from the dense registration of the skull.
    """
    try:
        to_head, _ = input_frame(landmarks)
    except (WorkbenchError, ValueError):
        to_head = _register(skull, landmarks, str(settings.sex or "male"), orient).input_to_head
    skull_h = skull.transformed(to_head).outward()
    plan = plan_dowels(skull_h, landmarks.transformed(to_head), settings)
    active = plan.active()
    back = np.linalg.inv(to_head)
    origins = _to(back, np.array([d.origin for d in active])) if active else np.zeros((0, 3))
    tips = _to(back, np.array([d.tip for d in active])) if active else np.zeros((0, 3))
    return DowelPreview(plan, origins, tips, tuple(d.code for d in active))


# ------------------------------------------------------------------ fit
def fit_inputs(case: Case, *, use_guides: bool = True, ensemble: int = 0) -> FitInputs:
    """GUI thread: the snapshot of ``case`` the worker fits (stored guides checked here)."""
    return FitInputs.from_case(case, use_guides=use_guides, ensemble=ensemble)


#: a fit's stages as its progress messages begin, with the fraction of the whole fit done
#: when each starts (measured on 100k-triangle skulls: the registration is ~70 % of it)
FIT_STAGES = (
    ("registering the reference skull and fitting", 0.01),
    ("orienting the skull", 0.02),
    ("second opinion", 0.2),
    ("posing the mandible", 0.32),
    ("registering the reference skull onto the bone", 0.4),
    ("planning the dowels", 0.72),
    ("fitting the head", 0.74),
    ("published guide predictions", 0.96),
    ("ensemble", 0.97),
    ("build faces", 0.98),
)
#: the same for a refit that reuses the registration (dowels, head fit and builds only)
REFIT_STAGES = (
    ("planning the dowels", 0.02),
    ("fitting the head", 0.15),
    ("published guide predictions", 0.85),
    ("ensemble", 0.87),
    ("build faces", 0.9),
)
#: what Suggest does: the registration alone
SUGGEST_STAGES = (
    ("orienting the skull", 0.02),
    ("second opinion", 0.3),
    ("posing the mandible", 0.45),
    ("registering the reference skull onto the bone", 0.55),
)


def staged(
    report: Callable[[str, float], None] | None, stages: Sequence[tuple[str, float]]
) -> Callable[[str], None]:
    """A ``progress(message)`` for the services that turns their stage messages into
    ``report(step, fraction)`` calls (``stages``: message start → fraction done).

    Messages of no stage keep the last fraction.  ``report`` may raise
    :class:`~workbench.core.errors.Cancelled` (a job's token), which stops the
    fit at that stage.
    """
    done = [0.0]

    def say(message: str) -> None:
        for start, fraction in stages:
            if message.startswith(start):
                done[0] = max(done[0], fraction)
                break
        if report is not None:
            report(message.rstrip(" .") or "working", done[0])

    return say


def fit_face(
    inputs: FitInputs,
    report: Callable[[str, float], None] | None = None,
    registration: SkullRegistration | None = None,
) -> FitResult:
    """Worker: reconstruct the face exactly as ``workbench reconstruct`` does.

    Stored guides are used as they are; without them Kähler's classic guides
    are computed from the skull, and computed guides that fail their
    plausibility checks are switched off with a warning
    (:func:`workbench.services.reconstruction.service.run_fit`).  ``report(step,
    fraction)`` hears the stages (and may cancel); ``registration`` is an
    earlier fit's, reused (:func:`~workbench.services.reconstruction.service.reusable_registration`).
    """
    stages = FIT_STAGES if registration is None else REFIT_STAGES
    return run_fit(inputs, progress=staged(report, stages), registration=registration)


def guide_geometry(fit: FitResult) -> tuple[list[tuple[np.ndarray, np.ndarray]], np.ndarray]:
    """Enabled guides as drawable segments and points in the input frame (mm).

    A vertical line (x = value) and a horizontal line (y = value) are drawn
    in the frontal plane just in front of the fitted face (head frame, z =
    the face's front + 5 mm); a lateral point (y, z) sits on the midline.
    """
    skin = fit.recon.head.skin.vertices
    z_front = float(skin[:, 2].max()) + 5.0
    segments, points = [], []
    for g in fit.guides:
        if not g.enabled:
            continue
        if g.kind == "vline":
            a, b = [g.value[0], -75.0, z_front], [g.value[0], 5.0, z_front]
        elif g.kind == "hline":
            a, b = [-35.0, g.value[0], z_front], [35.0, g.value[0], z_front]
        else:
            points.append([0.0, g.value[0], g.value[1]])
            continue
        ends = fit.recon.to_input(np.array([a, b], float))
        segments.append((ends[0], ends[1]))
    pts = fit.recon.to_input(np.array(points, float)) if points else np.zeros((0, 3))
    return segments, pts


def guides_state(guides: list[Guide] | tuple[Guide, ...]) -> GuideList:
    """Guides as the case's ``guides`` part (``SetGuides``)."""
    return GuideList(tuple(guides_to_json(guides)))
