"""A fitted face kept with its case: stored at save, shown at once when the case is reopened.

The fit (:class:`~workbench.services.reconstruction.service.FitResult`: the
fitted head, its guides, build faces, dowels, registration and figures) is a
*derived* result: the case's inputs (skull, landmarks, dowel settings,
orientation, guides) determine it.  It is kept in the case file so that a
reopened case shows the face, the guides, the build faces and an age study
of the reconstruction without fitting again, and it is **hashed**: the state
records the digest of the inputs it was fitted from (:func:`inputs_digest`),
so a reader can tell whether it still belongs to the case (*current*) or an
input has changed since (*stale*).

The state is plain data (:mod:`workbench.core.value_state`): only the classes
of :data:`REGISTRY` are rebuilt, from their fields; nothing is unpickled.
Units and frames are those of the fit itself (mm; the head frame for the
head, the input frame for landmarks and the face, see
:class:`~workbench.services.reconstruction.reconstruct.Reconstruction`).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, replace
from typing import Any

import workbench
from workbench.core import value_state
from workbench.core.jaw_pose import JawPose, Occlusion
from workbench.core.landmarks import Landmark, LandmarkSet
from workbench.core.mesh import Mesh
from workbench.core.rigid_search import PoseResult
from workbench.model.case import Case
from workbench.model.muscles import MuscleGrid, SurfacePoints
from workbench.model.reconstruction_setup import DowelSettings, GuideList, Orientation
from workbench.model.template import TemplateHead
from workbench.services.guides.classic import Guide
from workbench.services.guides.rules import Prediction
from workbench.services.reconstruction.build_faces import BuildFaces
from workbench.services.reconstruction.reconstruct import Reconstruction
from workbench.services.reconstruction.service import DowelPreview, FitInputs, FitResult
from workbench.services.registration.result import PartReport, SkullRegistration
from workbench.services.tissue.dowels import Dowel, DowelPlan
from workbench.services.tissue.tissue_model import SiteCalibration, TissueField, TissueSettings

#: the key of the fit among a case's derived results (``case.derived``)
KEY = "fit"
#: the version of this state's layout (a reader refuses other versions: fit again)
LAYOUT = 1

#: the classes a stored fit may contain: the only ones ever built when reading it
REGISTRY: Mapping[str, type] = {
    cls.__name__: cls
    for cls in (
        FitResult,
        FitInputs,
        Reconstruction,
        TemplateHead,
        Mesh,
        Landmark,
        LandmarkSet,
        MuscleGrid,
        SurfacePoints,
        DowelSettings,
        Orientation,
        GuideList,
        TissueSettings,
        Guide,
        Prediction,
        BuildFaces,
        DowelPreview,
        DowelPlan,
        Dowel,
        SkullRegistration,
        PartReport,
        PoseResult,
        JawPose,
        Occlusion,
        TissueField,
        SiteCalibration,
    )
}


class StoredFitError(ValueError):
    """A stored fit cannot be read (another layout, a damaged state): fit the face again."""


def inputs_digest(inputs: FitInputs) -> str:
    """SHA-256 (hex) of everything a fit is made from (the skull's arrays included).

    The examiner's name is left out: it goes into the report, not into the face.
    """
    inputs = replace(inputs, examiner="")
    return value_state.digest(value_state.encode(inputs, REGISTRY, "inputs"))


def fit_to_state(fit: FitResult, case: Case | None = None) -> dict[str, Any]:
    """The plain state of ``fit`` to keep in the case (arrays left as arrays).

    The inputs digest is that of ``fit.inputs``, or, given ``case``, of the
    case's inputs as they are now (with the fit's guide and ensemble choices):
    a job that records what the fit found (suggested landmarks) into its case
    stores the face as belonging to the case it writes.
    """
    if fit.inputs is None:
        raise StoredFitError("the fit does not record its inputs, so it cannot be kept")
    inputs = fit.inputs
    if case is not None:
        inputs = FitInputs.from_case(case, use_guides=inputs.use_guides, ensemble=inputs.ensemble)
    return {
        "layout": LAYOUT,
        "software": workbench.__version__,
        "inputs_digest": inputs_digest(inputs),
        "fit": value_state.encode(fit, REGISTRY, "fit"),
    }


@dataclass(frozen=True)
class StoredFit:
    """A fit read back from a case: the fit, and whether it still matches the case.

    ``current``: the case's inputs (with the fit's guide and ensemble choices)
    are those it was fitted from.  ``software``: the version that fitted it.
    """

    fit: FitResult
    current: bool
    software: str


def fit_from_state(state: Mapping[str, Any], case: Case) -> StoredFit:
    """The fit kept in ``case`` (see :func:`fit_to_state`), checked against the case's inputs.

    Raises
    ------
    StoredFitError
        Another layout, or a state that does not decode to a fit.
    """
    if state.get("layout") != LAYOUT:
        raise StoredFitError(
            f"the stored face has layout {state.get('layout')!r}, this version reads "
            f"{LAYOUT}: reconstruct the face again"
        )
    try:
        fit = value_state.decode(state["fit"], REGISTRY, "fit")
    except (KeyError, value_state.StateError) as exc:
        raise StoredFitError(f"the stored face cannot be read ({exc}): reconstruct again") from exc
    if not isinstance(fit, FitResult) or fit.inputs is None:
        raise StoredFitError("the stored result is not a fitted face: reconstruct again")
    try:
        now = FitInputs.from_case(
            case, use_guides=fit.inputs.use_guides, ensemble=fit.inputs.ensemble
        )
        current = inputs_digest(now) == state.get("inputs_digest")
    except (ValueError, value_state.StateError):  # the case cannot be fitted as it is
        current = False
    return StoredFit(fit, current, str(state.get("software", "")))
