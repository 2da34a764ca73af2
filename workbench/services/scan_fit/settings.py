"""The scan fit's tunable constants and its result types (:mod:`workbench.services.scan_fit.fit`).

The thresholds that decide what a scan is (a face, a partial face, a head of
a head's size), the skin registration's levels, the limits of a fit that asks
for a check, the thin-sheet and bone checks' sizes, and the dataclasses
:class:`ScanFit` (the result of :func:`~workbench.services.scan_fit.fit.fit_scan`)
and :class:`PreparedScan` (a scan made ready to fit:
:func:`~workbench.services.scan_fit.checks.prepare_scan`).

Units mm.  Distances are measured in the head frame of the fitted person
(x to the subject's left, y up, z toward the face, Frankfort Horizontal at
y = 0), or in the scan file's frame where a docstring says so.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from workbench.core.detail_layer import DetailLayer
from workbench.core.frame import apply_transform
from workbench.core.mesh import Mesh
from workbench.core.nonrigid import Level
from workbench.model.template import TemplateHead

#: a message to show the user while the fit runs
Progress = Callable[[str], None]

#: fewer triangles than this is not a scan of a face
MIN_SCAN_TRIANGLES = 1000
#: largest side of a face, head or head-and-shoulders (bust) scan, mm
SCAN_EXTENT_MM = (60.0, 700.0)
#: the skin registration's levels on a scan: the template build's, then finer
SCAN_LEVELS = (
    Level(24.0, 1.0, 8.0, 6),
    Level(14.0, 0.6, 5.0, 6),
    Level(8.0, 0.4, 3.0, 6),
    Level(5.0, 0.3, 2.0, 6),
    Level(3.5, 0.25, 1.5, 6),
    Level(2.5, 0.2, 1.0, 6),
)
#: radius over which the skin normal at a landmark is averaged (mm)
NORMAL_RADIUS_MM = 6.0
#: regulariser of the inner parts' thin-plate spline
INNER_SMOOTHING = 2.0
#: scan vertices this close to a hole or field-of-view rim are not counted (mm)
RIM_EXCLUDE_MM = 4.0
#: a scan vertex counts as "the head" in the report when its belief exceeds this
HEAD_WEIGHT = 0.5
#: a fitted skin vertex is "on the scan" when the scan surface is this close (mm) ...
#: (a miss of the fit, e.g. a sharper nose tip than a coarse scan's, is not a hole:
#: holes are told by the rim-faded belief of the closest point)
ON_SCAN_MM = 5.0
#: ... at a point of belief above HEAD_WEIGHT facing the same side (creases at the mouth
#: corners and canthi turn the normals of a coarse scan by up to ~90°)
ON_SCAN_COS = 0.0
#: a second connected piece this large (area fraction of the largest) and this far away
#: (mm, between centroids) is a second head or body, not a stray fragment
SECOND_PIECE = (0.4, 150.0)
#: below this fraction of the reference face supported by the scan, it is not a face
MIN_FACE_SUPPORT = 0.6
#: ... nor below this fraction of the rigidly placed reference face within 5 mm of it
#: (:func:`workbench.core.face_pose.place_face`), or of its nose while the face's is weak
MIN_PLACED_FACE = 0.5
MIN_PLACED_NOSE = 0.45
#: ... the nose's share decides only while the face's is below this
NOSE_DOUBT_FACE = 0.6
#: a reference face vertex whose closest scan point lies beyond the scan's rim (an open
#: edge, a field-of-view lid) farther than this (mm) is not covered by the scan: part of a
#: partial face the scan does not show, not a mismatch of its shape
COVER_MM = 5.0
#: a scan covering at least this share of the reference face is a whole face: the face
#: placement's verdict on it stands (a ball, a hand: no rim to end the face at)
WHOLE_FACE_COVERAGE = 0.9
#: a partial face is laid on the scan from this many of the search's poses
PARTIAL_STARTS = 3
#: ... each scored by its face loss over the covered vertices and this cost for each
#: uncovered one (below a mismatch's 1: a pose sliding the face off the scan gains nothing)
UNCOVERED_COST = 0.5
#: a fit with more fold-overs (outside the reference's mouth-corner seam) or new
#: self-crossings than this asks for a check (exit 3); real scans give 0
MAX_FOLD_OVERS = 4
MAX_NEW_CROSSINGS = 4
#: a partial face (WHOLE_FACE_COVERAGE) must match over more of the part it shows than a
#: whole face over all of it (MIN_FACE_SUPPORT): less of it fixes the pose (the headsq
#: skin cut below the nose or at the teeth 0.78-0.83; cut at the orbits, the face laid a
#: nose lower, 0.64)
MIN_PARTIAL_SUPPORT = 0.7
#: the skin landmark a partial face must show
NOSE_TIP = "prn"
#: a partial face's inferred share is noted above this
INFERRED_NOTE_SHARE = 0.05
#: an ear with more than this share of its vertices beyond the scan's rim is cut by it,
#: and held to the reference's shape instead of following the scan's
EAR_REGIONS = ("ear_l", "ear_r")
CUT_EAR_SHARE = 0.1
#: the scan crossing itself in this many triangle pairs, spread over this length (mm), is
#: two surfaces through each other (two heads, a head merged twice); real scans give 0
SHELL_CROSSINGS = (40, 60.0)
#: --bone must overlap the scan: at least this share of it within BONE_BOX_MARGIN_MM of the
#: scan's bounding box (a partial face scan leaves the jaw's bone below it)
BONE_IN_BOX = 0.25
BONE_BOX_MARGIN_MM = 20.0
#: ... and lie under the skin, not on it: a --bone with this share of its vertices within
#: BONE_ON_SKIN_MM of the scan is the skin itself (real bone: the thinnest facial tissue
#: is ~3 mm)
BONE_ON_SKIN = 0.5
BONE_ON_SKIN_MM = 1.0
#: a placed face with a loss below this sits well (the test skins 0.02-0.13; real scans
#: 0.25-0.45, a wrong pose's 0.45-0.65): the search's runners-up are then not tried
CLEAR_FACE_LOSS = 0.2
#: texture atlas side (texels) of a coloured scan's fitted skin: each texel samples the
#: scan (2048 took ~21-28 s on a 300k-triangle scan, 1024 ~4 s)
COLOUR_ATLAS_SIZE = 1024
INNER_PARTS = ("cranium", "mandible", "upper_teeth", "lower_teeth", "tongue", "eyes")
BONE_PARTS = ("cranium", "mandible")
#: recorded in the provenance; 2: the fine detail layer over the subdivided skin
FIT_VERSION = 2
#: a note when this share of the counted face scan vertices lies over the skin's openings
OPENINGS_WARN_SHARE = 0.004
#: a scan sheet at most this thick (mm, along its inward normal to where the ray leaves
#: it) is not the face's skin (a cord or strap over the face, a hair strand, a segmentation
#: fin; the VHP female and male CTs have a ~5 mm cord around the face, lifted ~4 mm off
#: the female's forehead, its top ~9 mm out) when, before the fit, more of the scan lies
#: beneath it within SHEET_GAP_MM (the skin under the cord; not where the reference has
#: its own thin parts over air: SHEET_PARTS), or when, after it, it lies wholly
#: SHEET_OUTSIDE_MM outside the fitted skin (at both of its sides: a fin).  Chosen on the
#: VHP female skin, judged on the other cases
SHEET_MAX_MM = 6.0
SHEET_GAP_MM = 12.0
SHEET_OUTSIDE_MM = 1.0
#: the reference's regions whose skin is a thin sheet over air (the alae over the
#: nostrils, the lips at their slit, the lids, the ears' folds)
SHEET_PARTS = (
    "nose",
    "upper_lip",
    "lower_lip",
    "eyelid_upper_l",
    "eyelid_upper_r",
    "eyelid_lower_l",
    "eyelid_lower_r",
    "ear_l",
    "ear_r",
)
#: a note when this share of the face scan vertices are such sheets
SHEET_WARN_SHARE = 0.002
#: two skin landmarks this far apart (mm) on the reference cannot share a point on a scan
LANDMARKS_APART_MM = 5.0
#: a first-guess landmark's confidence falls to 1/e at this distance from the scan (mm)
CONFIDENCE_MM = 1.5
#: ... and is at most this over a hole (its position is the reference's, not measured)
HOLE_CONFIDENCE = 0.2
#: bone that reaches through the fitted face skin is moved back under it to this depth (mm)
BONE_CLEARANCE_MM = 0.5
#: ... with a Gaussian falloff of this radius around each skin vertex it reached (mm)
BONE_PUSH_RADIUS_MM = 5.0
#: the uniform tissue depth of the baseline the estimated skull must beat (VALIDATION.md: 6 mm)
BASELINE_DEPTH_MM = 6.0


@dataclass(frozen=True)
class ScanFit:
    """The reference head fitted to a scan.

    Attributes
    ----------
    head : TemplateHead
        In the fitted person's head frame, mm.
    input_to_head : (4, 4)
        Scan coordinates (mm) → head frame (a reflection when ``mirrored_input``).
    skin_on_scan : (n_skin,) bool
        Skin vertices the scan supports (the rest keep the reference's shape).
    figures : dict
        The fit report (distances mm, fractions, seconds).
    scan : Mesh, optional
        The scan in the head frame (mm), for pictures and colour transfer.
    scan_distance : (n_scan,) float, optional
        Each scan vertex's distance to the fitted skin (mm); NaN where it is
        not counted in the face-region figures (outside the face, near a
        hole or field-of-view rim, or not the head).
    detail : DetailLayer, optional
        The scan's fine detail over the Loop-subdivided fitted skin
        (:mod:`workbench.core.detail_layer`); ``detail.apply(head.skin.vertices)``
        is the detailed skin, and re-details an animated or aged skin too.
    """

    head: TemplateHead
    input_to_head: np.ndarray
    mirrored_input: bool
    skin_on_scan: np.ndarray
    figures: dict
    warnings: tuple[str, ...] = ()
    scan: Mesh | None = None
    scan_distance: np.ndarray | None = None
    detail: DetailLayer | None = None

    def to_input(self, points: np.ndarray) -> np.ndarray:
        """Head-frame points back in the scan's coordinates."""
        return apply_transform(np.linalg.inv(self.input_to_head), np.reshape(points, (-1, 3)))


@dataclass(frozen=True)
class PreparedScan:
    """A scan file's mesh made ready to fit (the file's frame, mm;
    :func:`~workbench.services.scan_fit.checks.prepare_scan`).

    Attributes
    ----------
    mesh : Mesh
        The working scan: coincident vertices welded, zero-area and repeated
        triangles dropped, distant stray pieces left out, each piece wound
        consistently and outward, simplified to at most
        :data:`~workbench.core.limits.SCAN_WORK_TRIANGLES`.
    vertex_of : (n_file_vertices,) int, optional
        The working vertex of each vertex of the file's mesh (-1: left out);
        None when the scan was simplified (its vertices are new).
    face_source : (n_faces,) int, optional
        The file's triangle of each working triangle (its corners possibly in
        reverse order); None when simplified.
    notes : tuple of str
        What the user is told (pieces left out, simplification).
    repairs : tuple of str
        Harmless repairs made silently (for the report).
    file_triangles : int
        Triangles in the file's mesh.
    """

    mesh: Mesh
    vertex_of: np.ndarray | None
    face_source: np.ndarray | None
    notes: tuple[str, ...]
    repairs: tuple[str, ...]
    file_triangles: int

    @property
    def figures(self) -> dict:
        """The preparation for ``fit_report.json``."""
        return {
            "file_triangles": self.file_triangles,
            "working_triangles": int(self.mesh.n_faces),
            "simplified": self.vertex_of is None,
            "repairs": list(self.repairs),
            "notes": list(self.notes),
        }
