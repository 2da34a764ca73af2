"""The one skull → face pipeline, shared by ``workbench reconstruct``, scripts and the window.

Two steps:

1. :meth:`FitInputs.from_case` takes a snapshot of what a fit needs from a
   case — the working skull, its landmarks, the typed settings
   (:mod:`workbench.model.reconstruction_setup`: dowels, orientation,
   guides) — plus the run options that are not part of the case (reference
   pack(s), published rules, guides on or off, ensemble size).  Every field
   is an immutable value, so the snapshot can go to a worker thread while
   the user goes on editing the case.
2. :func:`run_fit` fits the reference head over the skull
   (:func:`workbench.services.reconstruction.reconstruct.reconstruct`: dense registration,
   dowels from the depth table, the tissue model, the guides as the last
   warp), forms the library consensus when several reference packs are
   given, draws the uncertainty ensemble and computes the published-rule
   predictions.  It never changes a case: callers apply the results through
   commands (the job pushes the fitted landmark set; the window draws).

Units mm.  Inputs and the returned face, landmarks and dowel preview are in
the skull file's frame (the specimen's input frame); the fit itself runs in
the head frame (x to the subject's left, y up, z toward the face, Frankfort
Horizontal), where ``skull_h`` and the guide values are.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable, Sequence
from concurrent.futures import Future
from dataclasses import dataclass, field, replace
from os import PathLike
from pathlib import Path
from typing import Any

import numpy as np

from workbench.core.errors import InputError, WorkbenchError
from workbench.core.frame import apply_transform
from workbench.core.isosurface import decimate
from workbench.core.landmarks import LandmarkSet
from workbench.core.mesh import Mesh
from workbench.model.case import Case
from workbench.model.reconstruction_setup import DowelSettings, GuideList, Orientation
from workbench.model.template import TemplateHead
from workbench.services.guides.classic import Guide
from workbench.services.guides.fit_guides import FitGuides, stored_guides
from workbench.services.guides.rules import Prediction, published_predictions
from workbench.services.reconstruction.build_faces import BuildFaces, build_faces
from workbench.services.reconstruction.fit_checks import check_face_fits_skull, check_fit_settings
from workbench.services.reconstruction.reconstruct import (
    FitSettings,
    Reconstruction,
    ensemble_spread,
    reconstruct,
)
from workbench.services.registration.result import SkullRegistration
from workbench.services.templates.cache import reference_head
from workbench.services.tissue.dowels import DepthSettings, DowelPlan, build_model_for
from workbench.services.tissue.tissue_model import TissueSettings

Progress = Callable[[str], None]
PathArg = str | PathLike[str]
#: skulls larger than MAX_WORKING_TRIANGLES are decimated to WORKING_TRIANGLES for the fit.
#: Skulls over 120k triangles are brought to the same size, so the registration sees the
#: same detail whatever resolution the exporting program chose (before, a 240k-triangle
#: skull was fitted as it was and a 260k one at 100k).  On the robustness corpus's 57
#: variants of 200k triangles this moved orientation-right from 40 % to 75 % on the VHP
#: male and from 83 % to 70 % on the VHP female (headsq 86 % both): 84.3 % right over
#: all 230 variants against 82.6 %, within what one iso level changes.
MAX_WORKING_TRIANGLES = 120_000
WORKING_TRIANGLES = 100_000
#: fit internals when the caller gives none (frozen, shared)
DEFAULT_TISSUE = TissueSettings()


def depth_settings(dowels: DowelSettings) -> DepthSettings:
    """The dowel planner's settings for the case's dowel settings."""
    return DepthSettings(
        table=dowels.table,
        sex=dowels.sex,
        build=dowels.build,
        overrides=dict(dowels.overrides),
        excluded=frozenset(dowels.excluded),
    )


def tissue_settings(dowels: DowelSettings, base: TissueSettings = DEFAULT_TISSUE) -> TissueSettings:
    """``base`` (fit internals) with the case's tissue model and region factors."""
    return replace(base, model=dowels.tissue_model, region_factors=dict(dowels.region_factors))


@dataclass(frozen=True)
class FitInputs:
    """Everything one fit needs, as immutable values (see the module docstring).

    Attributes
    ----------
    skull : Mesh
        The working skull, mm, input frame.
    landmarks : LandmarkSet or None
        Skull landmarks (input frame); None: all found by the registration.
    dowels : DowelSettings
    orientation : Orientation or None
        None: the orientation is searched from the bone.
    guides : GuideList or None
        Guides stored in the case; None: computed from the skull.
    template : path or None
        Reference pack; None: the built-in head of ``dowels.sex``.
    templates : tuple of paths
        Two or more packs: one fit each, the face their per-vertex median.
    rules : tuple of str
        Published rule ids replacing the classic guide of their feature.
    use_guides : bool
        False fits without any guide.
    ensemble : int
        Number of depth draws for the spread map (0: none).
    examiner : str
    tissue : TissueSettings
        Fit internals (pinning, minimum tissue, smoothing); the model and
        region factors always come from ``dowels``.
    """

    skull: Mesh
    landmarks: LandmarkSet | None
    dowels: DowelSettings = field(default_factory=DowelSettings)
    orientation: Orientation | None = None
    guides: GuideList | None = None
    template: Path | None = None
    templates: tuple[Path, ...] = ()
    rules: tuple[str, ...] = ()
    use_guides: bool = True
    ensemble: int = 0
    examiner: str = ""
    tissue: TissueSettings = field(default_factory=TissueSettings)

    def __post_init__(self) -> None:
        if not isinstance(self.skull, Mesh) or not self.skull.n_faces:
            raise InputError("reconstruction", "there is no skull to fit the face to")
        if (
            isinstance(self.ensemble, bool)
            or not isinstance(self.ensemble, int)
            or self.ensemble < 0
        ):
            raise InputError(
                "ensemble", f"the number of fits must be 0 or more, got {self.ensemble!r}"
            )
        templates = tuple(Path(p) for p in self.templates)
        template = Path(self.template) if self.template is not None else None
        if template is None and templates:
            template = templates[0]
        object.__setattr__(self, "templates", templates)
        object.__setattr__(self, "template", template)
        object.__setattr__(self, "rules", tuple(str(r) for r in self.rules))
        if self.landmarks is not None and not len(self.landmarks):
            object.__setattr__(self, "landmarks", None)

    @classmethod
    def from_case(
        cls,
        case: Case,
        *,
        template: PathArg | None = None,
        templates: Sequence[PathArg] = (),
        rules: Sequence[str] = (),
        use_guides: bool = True,
        ensemble: int = 0,
        tissue: TissueSettings = DEFAULT_TISSUE,
    ) -> FitInputs:
        """A snapshot of ``case`` (skull, skull landmarks, dowels, orientation, guides).

        The stored guides are checked here (an :class:`InputError` names the
        guide at fault), so a bad list fails before any work starts.
        """
        if case.specimen.mesh is None:
            raise InputError("reconstruction", "the case has no skull yet", "open a skull first")
        stored_guides(case.guides)
        return cls(
            case.specimen.mesh,
            case.landmarks["skull"],
            case.dowels,
            case.orientation,
            case.guides,
            None if template is None else Path(template),
            tuple(Path(p) for p in templates),
            tuple(rules),
            use_guides,
            int(ensemble),
            case.meta.examiner,
            tissue,
        )

    @property
    def fit_settings(self) -> FitSettings:
        return FitSettings(
            depth=depth_settings(self.dowels),
            tissue=tissue_settings(self.dowels, self.tissue),
            jaw=self.dowels.jaw,
        )

    @property
    def hint(self) -> tuple | None:
        """The registration's orientation hint ``(anterior, superior[, left])`` or None."""
        return None if self.orientation is None else self.orientation.hint


@dataclass(frozen=True)
class DowelPreview:
    """A dowel plan with origins and tips mapped into the input frame (mm)."""

    plan: DowelPlan
    origins: np.ndarray  # (n, 3) input frame mm, active dowels
    tips: np.ndarray  # (n, 3)
    codes: tuple[str, ...]

    @classmethod
    def of(cls, plan: DowelPlan, to_input: Callable[[np.ndarray], np.ndarray]) -> DowelPreview:
        """The active dowels of ``plan`` (head frame) mapped by ``to_input``."""
        active = plan.active()
        if not active:
            return cls(plan, np.zeros((0, 3)), np.zeros((0, 3)), ())
        return cls(
            plan,
            to_input(np.array([d.origin for d in active])),
            to_input(np.array([d.tip for d in active])),
            tuple(d.code for d in active),
        )


@dataclass(frozen=True)
class FitResult:
    """A reconstruction with the guides it used and, optionally, its spread.

    Attributes
    ----------
    recon : Reconstruction
        Its ``warnings`` include the guides switched off and the rules not applied.
    head : TemplateHead
        The reference head fitted (the first pack of a library).
    skull_h : Mesh
        The working skull in the head frame.
    guides : tuple of Guide
    spread : (n_skin_vertices,) float or None
        Ensemble spread (mm), None without an ensemble.
    preview : DowelPreview
    predictions : tuple of Prediction
    inputs : FitInputs
        What the fit was run with (the report is built from it).
    notes : tuple of str
        Notes about the run itself (working skull decimated, predictions unavailable).
    rejected : tuple of str
        Guides switched off and rules not applied (also in ``recon.warnings``).
    references : dict or None
        Library consensus: ``{"heads": [{"id", "path"}], "spread": (n,) mm}``.
    seconds : dict
        ``{"fit", "ensemble", "builds"}`` wall times.
    builds : BuildFaces or None
        The slender, average and heavy faces and the uncertainty band
        (:mod:`workbench.services.reconstruction.build_faces`); None where the depths cannot
        vary with build (a uniform mean + k SD, a table's build group, a table
        without SDs, the reference's own tissue, a library consensus).
    """

    recon: Reconstruction
    head: TemplateHead
    skull_h: Mesh
    guides: tuple[Guide, ...]
    spread: np.ndarray | None
    preview: DowelPreview
    predictions: tuple[Prediction, ...] = ()
    inputs: FitInputs | None = None
    notes: tuple[str, ...] = ()
    rejected: tuple[str, ...] = ()
    references: dict[str, Any] | None = None
    seconds: dict[str, float] = field(default_factory=dict)
    builds: BuildFaces | None = None

    @property
    def warnings(self) -> tuple[str, ...]:
        """Every note of the fit: the run's, then the reconstruction's."""
        return self.notes + tuple(self.recon.warnings)

    @property
    def spread_map(self) -> np.ndarray | None:
        """The ensemble spread, else the spread between the references of a library."""
        if self.spread is not None or self.references is None:
            return self.spread
        return self.references["spread"]


_PREFETCH_LOCK = threading.Lock()
#: the decimation :func:`prefetch_working_skull` started last: (vertices, faces, result)
_prefetch: tuple[np.ndarray, np.ndarray, Future] | None = None


def prefetch_working_skull(skull: Mesh) -> None:
    """Start decimating a large ``skull`` now, in the helper process
    (:mod:`workbench.core.helper_process`; a thread waits on it), so that the checks
    and the case set-up that follow a read run meanwhile on the other core; the next
    :func:`working_skull` of the same mesh takes the result.  Small skulls: nothing.
    One at a time: a newer prefetch replaces one not taken."""
    global _prefetch
    if skull.n_faces <= MAX_WORKING_TRIANGLES:
        return
    from workbench.core import helper_process

    future: Future = Future()
    vertices, faces = skull.vertices, skull.faces

    def work() -> None:
        try:
            future.set_result(
                helper_process.call(
                    "workbench.core.isosurface:decimate", vertices, faces, WORKING_TRIANGLES
                )
            )
        except BaseException as exc:  # noqa: BLE001 - handed to the one who waits
            future.set_exception(exc)

    with _PREFETCH_LOCK:
        _prefetch = (vertices, faces, future)
    threading.Thread(target=work, name="working-skull", daemon=True).start()


def _prefetched(skull: Mesh) -> Future | None:
    """The decimation :func:`prefetch_working_skull` started for a mesh equal to ``skull``
    (handed out once)."""
    global _prefetch
    with _PREFETCH_LOCK:
        if _prefetch is None:
            return None
        v, f, future = _prefetch
        same = (v is skull.vertices or np.array_equal(v, skull.vertices)) and (
            f is skull.faces or np.array_equal(f, skull.faces)
        )
        if not same:
            return None
        _prefetch = None
        return future


def working_skull(skull: Mesh, say: Progress = lambda _m: None) -> tuple[Mesh, list[str]]:
    """The skull the fit works on (large scans decimated) and a note if it was."""
    if skull.n_faces <= MAX_WORKING_TRIANGLES:
        return skull, []
    # Kähler §8.6.4: a 50-250k-triangle working mesh keeps the editor
    # responsive; the original stays in the case as evidence
    say(f"decimating the working skull {skull.n_faces} -> {WORKING_TRIANGLES} triangles ...")
    started = _prefetched(skull)
    if started is not None:
        v, f = started.result()
    else:
        v, f = decimate(skull.vertices, skull.faces, WORKING_TRIANGLES)
    work = Mesh(v, f)
    return work, [
        f"working skull decimated from {skull.n_faces} to {work.n_faces} triangles "
        "(the original file is kept as evidence)"
    ]


def reusable_registration(
    previous: FitResult | None, inputs: FitInputs
) -> SkullRegistration | None:
    """The registration of ``previous`` if a fit of ``inputs`` may reuse it, else None.

    It may when the skull (same vertices and faces), its orientation, the
    reference head (sex, pack) and the jaw handling are those it was made
    for, and the fit is of one reference head: an edit of landmarks, dowel
    depths or guides then moves dowels and skin targets, not the skull.
    """
    if previous is None or previous.inputs is None or previous.recon.registration is None:
        return None
    old = previous.inputs
    same_skull = old.skull is inputs.skull or (
        np.array_equal(old.skull.vertices, inputs.skull.vertices)
        and np.array_equal(old.skull.faces, inputs.skull.faces)
    )
    same = (
        same_skull
        and old.orientation == inputs.orientation
        and old.template == inputs.template
        and len(inputs.templates) <= 1
        and old.dowels.sex == inputs.dowels.sex
        and old.fit_settings.jaw == inputs.fit_settings.jaw
    )
    return previous.recon.registration if same else None


def run_fit(
    inputs: FitInputs,
    progress: Progress | None = None,
    *,
    registration: SkullRegistration | None = None,
) -> FitResult:
    """Fit the face as described by ``inputs`` (see the module docstring).

    ``registration``: the dense skull registration of an earlier fit of the
    same skull, orientation and reference head, reused (a refit after a
    landmark or guide edit: :func:`reusable_registration`); None registers.

    Raises
    ------
    WorkbenchError
        Unknown tables, rules, landmark codes, settings out of bounds
        (:func:`~workbench.services.reconstruction.fit_checks.check_fit_settings`), a failed
        registration, a face whose size does not fit the skull
        (:func:`~workbench.services.reconstruction.fit_checks.check_face_fits_skull`)...
    """
    say = progress or (lambda _m: None)
    t = time.perf_counter()
    dowels = inputs.dowels
    # cheap checks first: a bad table, build, ensemble or rule fails before the registration
    check_fit_settings(dowels, ensemble=inputs.ensemble, rules=inputs.rules)
    head = reference_head(dowels.sex, inputs.template)
    work, notes = working_skull(inputs.skull, say)
    fit = inputs.fit_settings
    guides = FitGuides(dowels, stored_guides(inputs.guides), inputs.rules, inputs.use_guides)
    say("registering the reference skull and fitting the head ...")
    recon = reconstruct(
        work,
        inputs.landmarks,
        head,
        settings=fit,
        guides=guides,
        hint=inputs.hint,
        progress=say,
        registration=registration,
    )
    references = None
    if len(inputs.templates) > 1:
        recon, references = library_consensus(recon, work, inputs, say)
    check_face_fits_skull(recon.face, inputs.skull)  # never a garbage face as a result
    reg = recon.registration
    if reg is not None and reg.occlusion is not None:
        skull_h = reg.target_h  # the skull with its jaw in occlusion, as the face was fitted
    else:
        skull_h = work.transformed(recon.input_to_head).outward()
    if recon.landmarks is None:  # reconstruct() always records the landmarks it used
        raise RuntimeError("the reconstruction carries no skull landmarks")
    lms_h = recon.landmarks.transformed(recon.input_to_head)
    rejected = tuple(guides.rejected)
    recon = replace(
        recon, warnings=recon.warnings + rejected + tuple(guides.problems(skull_h, lms_h))
    )
    say("published guide predictions ...")
    try:
        predictions = published_predictions(
            lms_h,
            dowels.sex,
            skull=skull_h,
            dowel_tips={d.code: d.tip for d in recon.plan.active()},
            problems=[],
        )
    except WorkbenchError as exc:  # informative only: a missing measurement must not stop it
        predictions = []
        notes.append(f"published guide predictions unavailable: {exc}")
    seconds = {"fit": time.perf_counter() - t}
    spread = None
    if inputs.ensemble > 0:
        say(f"ensemble of {inputs.ensemble} fits ...")
        t = time.perf_counter()
        spread = ensemble_spread(recon, head, skull_h, inputs.ensemble, settings=fit)
        seconds["ensemble"] = time.perf_counter() - t
    builds = None
    if references is None:
        say("build faces ...")
        t = time.perf_counter()
        builds = build_faces(
            recon, build_model_for(), min_tissue_mm=fit.min_tissue_mm, bone=skull_h
        )
        seconds["builds"] = time.perf_counter() - t
        if builds is None:
            notes.append(
                "one face only: a uniform mean + k SD build (use slender, average, heavy or "
                "bmi:X for the build model's three faces and band)"
                if isinstance(dowels.build, (int, float))
                else "one face only: the depths cannot vary with build here (a table group "
                "of that build, a table without SDs, or the reference's own tissue)"
            )
    for mesh in (recon.face, recon.head.skin):  # drawn smooth-shaded: normals here, in the
        _ = mesh.vertex_normals  # worker, not on the GUI thread
    return FitResult(
        recon,
        head,
        skull_h,
        tuple(guides.chosen),
        spread,
        DowelPreview.of(recon.plan, recon.to_input),
        tuple(predictions),
        inputs,
        tuple(notes),
        rejected,
        references,
        seconds,
        builds,
    )


def library_consensus(
    first: Reconstruction, work: Mesh, inputs: FitInputs, say: Progress
) -> tuple[Reconstruction, dict[str, Any]]:
    """Fit every reference pack of ``inputs.templates``; the face is their per-vertex median.

    All packs must share the first one's skin topology (packs built from the
    same base head do).  The spread between them (median distance of the
    members from the median face, mm) comes back with the head list.
    """
    faces = [first.face]
    heads = [{"id": first.head.template_id, "path": str(inputs.templates[0])}]
    for i, pack in enumerate(inputs.templates[1:], start=2):
        say(f"reference {i}/{len(inputs.templates)} ...")
        other = reconstruct(
            work,
            inputs.landmarks,
            reference_head(inputs.dowels.sex, pack),
            settings=inputs.fit_settings,
            hint=inputs.hint,
        )
        if (
            other.head.skin.n_vertices != first.head.skin.n_vertices
            or other.head.skin.n_faces != first.head.skin.n_faces
        ):
            raise WorkbenchError(
                f"reference {pack} does not share the skin topology of "
                f"{inputs.templates[0]} (packs must be built from one base head)"
            )
        faces.append(other.face)
        heads.append({"id": other.head.template_id, "path": str(pack)})
    stack = np.stack([f.vertices for f in faces])
    median = np.median(stack, axis=0)
    spread = np.median(np.linalg.norm(stack - median, axis=2), axis=0)
    skin_h = apply_transform(first.input_to_head, median)
    head = replace(
        first.head, meshes={**first.head.meshes, "skin": first.head.skin.with_vertices(skin_h)}
    )
    recon = replace(
        first,
        head=head,
        warnings=first.warnings
        + (
            f"face = per-vertex median of {len(faces)} reference heads (spread between them: median "
            f"{np.median(spread):.1f} mm)",
        ),
    )
    return recon, {"heads": heads, "spread": spread}
