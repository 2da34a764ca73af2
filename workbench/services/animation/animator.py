"""Animate a head: muscles, jaw and gaze drive the mass-spring skin (Kähler 2003, ch. 5-7).

One service for the CLI (``workbench animate``), scripts and, later, the
window::

    anim = Animator(reference_head("male"))
    anim.set_expression("happiness")
    anim.settle()
    mesh = anim.skin()

Units and frame: mm, seconds and degrees at this interface, head frame (x to
the subject's left, x = 0 midsagittal, y up, z toward the face, Frankfort
Horizontal at y = 0).  A head stored in another frame (a reconstruction's
``head/`` pack is in the skull file's frame) is animated in its Frankfort
frame, found from its skull landmarks, and the results are mapped back.

Expressions are muscle-activation vectors over the 24 muscles of Kähler's
Table 7.1, built from FACS action units (Ekman & Friesen 1978; Ekman,
Friesen & Hager 2002).  :data:`ACTION_UNITS` says which muscles produce
which AU; the six basic emotions follow the EMFACS prototypes (Friesen &
Ekman 1983; Ekman, Friesen & Hager 2002, *FACS Investigator's Guide*,
EMFACS).  Muscles of those AUs that the reference set does not have are
left out and said so: the levator palpebrae (its relaxation, AU43, is
modelled as a lid turn, :meth:`Animator.set_lids`; its contraction, AU5
upper lid raiser, is not), buccinator (AU14), zygomaticus minor, platysma.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from workbench.core.errors import InputError, WorkbenchError
from workbench.core.mass_spring import SkinParameters, SkinSimulation
from workbench.core.mesh import Mesh
from workbench.core.muscle_model import MuscleRig, MuscleSpec
from workbench.core.normals import vertex_normals
from workbench.core.spatial import MeshIndex
from workbench.model.template import TemplateHead
from workbench.services.registration.jaw import JAW_PARTS, axis_rotation

#: jaw rotation limits (degrees; positive opens). Maximal human opening is about 30-35°.
JAW_RANGE_DEG = (-5.0, 35.0)
#: jaw protrusion limits (mm along +z; negative retrudes)
PROTRUSION_RANGE_MM = (-3.0, 10.0)
#: gaze limits (degrees)
GAZE_RANGE_DEG = 45.0
#: passes of the visible skin's displacement filter (see :meth:`Animator.visible`): the
#: simulated nodes are the reference skin's vertices, 2-4 mm apart, and a mass-spring
#: net has no bending stiffness at that scale, so skin that muscles compress (the
#: frontalis' forehead, the orbicularis' lips, the chin over an opening jaw) buckles into
#: ripples one or two edges long.  Real facial skin is 1.5-4 mm thick over its fat and
#: folds with wavelengths of 10 mm and more, so the surface shown and exported is the
#: nodes' displacement field low-passed by this many umbrella passes (each half-way to
#: the neighbours' mean: a diffusion over ~3 edges, ~10 mm) and added to the rest shape,
#: which keeps the rest shape's own detail (a Delta-Mush-like filter, Mancewicz et al.
#: 2014, on displacements).  0 shows the raw nodes.
VISIBLE_SMOOTHING_PASSES = 10
#: the lid nodes' turn targets are this many times the turn that closes the lids: their
#: muscle springs meet the surrounding skin's springs about halfway (closure 1 left a
#: 5.3 mm gap between the lid margins, of 9.7 mm open), so the target is overdriven for the
#: settled margins to meet (measured on the reference head: 1.4 mm gap at closure 1, the
#: upper margin 1.0 mm above the lower, no crossing)
LID_GAIN = 2.0
#: a closing lid keeps this far outside the corneal apex (mm)
LID_CLEARANCE_MM = 0.6
#: skin regions that never move (Kähler simulates only the face)
STATIC_REGIONS = ("scalp", "ear_l", "ear_r", "neck")
#: skin regions without bone below (K 7.4.5: lips, cheeks; the eyelids lie on the eyes)
BONE_FREE_REGIONS = (
    "upper_lip",
    "lower_lip",
    "eyelid_upper_l",
    "eyelid_upper_r",
    "eyelid_lower_l",
    "eyelid_lower_r",
)


@dataclass(frozen=True)
class ActionUnit:
    """A FACS action unit as contractions of the reference muscles (sides pooled)."""

    number: int
    name: str
    muscles: Mapping[str, float]
    jaw_deg: float = 0.0
    protrusion: Mapping[str, float] = field(default_factory=dict)
    note: str = ""
    lids: float = 0.0


def _both(stem: str, c: float) -> dict[str, float]:
    return {f"{stem}_l": c, f"{stem}_r": c}


#: FACS action units the 24 muscles (and the jaw) can produce, at full intensity ("E")
ACTION_UNITS: dict[str, ActionUnit] = {
    "AU1": ActionUnit(
        1, "inner brow raiser", _both("frontalis_inner", 0.5), note="frontalis, pars medialis"
    ),
    "AU2": ActionUnit(
        2, "outer brow raiser", _both("frontalis_outer", 0.5), note="frontalis, pars lateralis"
    ),
    "AU4": ActionUnit(
        4,
        "brow lowerer",
        _both("corrugator", 0.5),
        note="corrugator supercilii (depressor glabellae, depressor supercilii not modelled)",
    ),
    "AU6": ActionUnit(
        6,
        "cheek raiser",
        _both("orbicularis_oculi_orbital", 0.4),
        note="orbicularis oculi, pars orbitalis",
    ),
    "AU7": ActionUnit(
        7,
        "lid tightener",
        _both("orbicularis_oculi_palpebral", 0.3),
        note="orbicularis oculi, pars palpebralis",
    ),
    "AU9": ActionUnit(
        9,
        "nose wrinkler",
        _both("levator_labii", 0.3),
        note="levator labii superioris alaeque nasi; the reference set has one levator labii per side",
    ),
    "AU10": ActionUnit(
        10, "upper lip raiser", _both("levator_labii", 0.45), note="levator labii superioris"
    ),
    "AU12": ActionUnit(
        12, "lip corner puller", _both("zygomaticus_major", 0.5), note="zygomaticus major"
    ),
    "AU15": ActionUnit(
        15,
        "lip corner depressor",
        _both("triangularis", 0.4),
        note="depressor anguli oris (triangularis)",
    ),
    "AU16": ActionUnit(
        16,
        "lower lip depressor",
        _both("quadratus_labii", 0.4),
        note="depressor labii inferioris (quadratus labii)",
    ),
    "AU17": ActionUnit(17, "chin raiser", {"mentalis": 0.5}, note="mentalis"),
    "AU18": ActionUnit(
        18,
        "lip pucker",
        {"orbicularis_oris_upper": 0.25, "orbicularis_oris_lower": 0.25},
        protrusion={"orbicularis_oris_upper": 0.4, "orbicularis_oris_lower": 0.4},
        note="incisivii labii superioris/inferioris: the orbicularis oris with protrusion",
    ),
    "AU20": ActionUnit(
        20, "lip stretcher", _both("risorius", 0.35), note="risorius (platysma not modelled)"
    ),
    "AU22": ActionUnit(
        22,
        "lip funneler",
        {"orbicularis_oris_upper": 0.1, "orbicularis_oris_lower": 0.1},
        protrusion={"orbicularis_oris_upper": 0.7, "orbicularis_oris_lower": 0.7},
        note="orbicularis oris, protruding",
    ),
    "AU23": ActionUnit(
        23,
        "lip tightener",
        {"orbicularis_oris_upper": 0.35, "orbicularis_oris_lower": 0.35},
        note="orbicularis oris",
    ),
    "AU24": ActionUnit(
        24,
        "lip pressor",
        {"orbicularis_oris_upper": 0.2, "orbicularis_oris_lower": 0.2},
        protrusion={"orbicularis_oris_upper": -0.3, "orbicularis_oris_lower": -0.3},
        note="orbicularis oris, lips pressed in",
    ),
    "AU26": ActionUnit(
        26, "jaw drop", {}, jaw_deg=10.0, note="jaw rotation (masseter, temporalis relaxed)"
    ),
    "AU27": ActionUnit(
        27,
        "mouth stretch",
        {"mylohyoideus": 0.3},
        jaw_deg=22.0,
        note="jaw rotation (FACS: pterygoids, digastric); the reference set's mylohyoideus "
        "stands in for the suprahyoid pull",
    ),
    "AU43": ActionUnit(
        43,
        "eyes closed",
        _both("orbicularis_oculi_palpebral", 0.2),
        lids=1.0,
        note="levator palpebrae relaxed (the lids close about the eye centre) with a little "
        "orbicularis oculi, pars palpebralis",
    ),
}


@dataclass(frozen=True)
class Expression:
    """Muscle contractions (0..1), sphincter protrusions (-1..1), jaw angle (degrees), lids (0..1)."""

    muscles: Mapping[str, float] = field(default_factory=dict)
    protrusion: Mapping[str, float] = field(default_factory=dict)
    jaw_deg: float = 0.0
    note: str = ""
    lids: float = 0.0


def from_action_units(units: Mapping[str, float], note: str = "") -> Expression:
    """An expression from ``{AU name: intensity 0..1}``: contractions add and are clipped to 1."""
    muscles: dict[str, float] = {}
    prot: dict[str, float] = {}
    jaw = 0.0
    lids = 0.0
    for name, k in units.items():
        au = ACTION_UNITS[name]
        for code, c in au.muscles.items():
            muscles[code] = min(1.0, muscles.get(code, 0.0) + k * c)
        for code, a in au.protrusion.items():
            prot[code] = float(np.clip(prot.get(code, 0.0) + k * a, -1, 1))
        jaw += k * au.jaw_deg
        lids += k * au.lids
    return Expression(muscles, prot, jaw, note, min(1.0, lids))


#: the palette: neutral, the six basic emotions (EMFACS prototypes), eye closure and every AU
EXPRESSIONS: dict[str, Expression] = {
    "neutral": Expression(note="all muscles relaxed, jaw closed"),
    "smile": from_action_units({"AU12": 1.0}, "AU12 (social smile)"),
    "happiness": from_action_units({"AU6": 1.0, "AU12": 1.0}, "AU6+12 (Duchenne smile)"),
    "sadness": from_action_units({"AU1": 1.0, "AU4": 1.0, "AU15": 1.0}, "AU1+4+15"),
    "surprise": from_action_units(
        {"AU1": 1.0, "AU2": 1.0, "AU26": 1.0}, "AU1+2+5B+26 (AU5 not modelled)"
    ),
    "fear": from_action_units(
        {"AU1": 1.0, "AU2": 1.0, "AU4": 1.0, "AU7": 1.0, "AU20": 1.0, "AU26": 0.8},
        "AU1+2+4+5+7+20+26 (AU5 not modelled)",
    ),
    "anger": from_action_units(
        {"AU4": 1.0, "AU7": 1.0, "AU23": 1.0}, "AU4+5+7+23 (AU5 not modelled)"
    ),
    "disgust": from_action_units({"AU9": 1.0, "AU15": 0.6, "AU16": 0.6}, "AU9+15+16"),
    "eye_closure": from_action_units({"AU43": 1.0}, "AU43"),
}
EXPRESSIONS.update(
    {name.lower(): from_action_units({name: 1.0}, ACTION_UNITS[name].name) for name in ACTION_UNITS}
)


def expression_label(name: str) -> str:
    """A palette name as the window lists it: ``"AU1 inner brow raiser"``, ``"happiness
    (AU6+12 (Duchenne smile))"``; unknown names as they are."""
    e = EXPRESSIONS.get(name)
    if e is None:
        return name
    if name.startswith("au") and name[2:].isdigit():
        return f"{name.upper()} {e.note}"
    return f"{name.replace('_', ' ')} ({e.note})" if e.note and name != "neutral" else name


def mix(weights: Mapping[str, float]) -> Expression:
    """Weighted sum of palette expressions (``{name: weight}``), contractions clipped to 0..1."""
    muscles: dict[str, float] = {}
    prot: dict[str, float] = {}
    jaw = 0.0
    lids = 0.0
    for name, w in weights.items():
        if name not in EXPRESSIONS:
            raise InputError(
                name, "is not an expression", "valid names: " + ", ".join(sorted(EXPRESSIONS))
            )
        e = EXPRESSIONS[name]
        for code, c in e.muscles.items():
            muscles[code] = float(np.clip(muscles.get(code, 0.0) + w * c, 0, 1))
        for code, a in e.protrusion.items():
            prot[code] = float(np.clip(prot.get(code, 0.0) + w * a, -1, 1))
        jaw += w * e.jaw_deg
        lids += w * e.lids
    return Expression(
        muscles, prot, jaw, "mix of " + ", ".join(weights), float(np.clip(lids, 0, 1))
    )


def _mask(n: int, head: TemplateHead, names: tuple[str, ...]) -> np.ndarray:
    m = np.zeros(n, bool)
    for name in names:
        if name in head.regions:
            m[np.asarray(head.regions[name], np.int64)] = True
    return m


def _to_head_frame(head: TemplateHead) -> tuple[TemplateHead, np.ndarray | None, bool]:
    """The head in the Frankfort frame of its skull landmarks, the 4x4 back (None: no move)
    and whether that back map is a reflection.

    Every head is animated in the frame its own landmarks define, so a head
    stored in another frame (a reconstruction's ``head/`` pack, in the skull
    file's frame) animates exactly like the same head stored in the head frame.
    A reconstruction of a mirrored skull file is stored mirrored with its
    triangles wound the other way; it is reflected back (the reference's own
    winding, which the muscles' triangles rely on) and its results reflected
    out again with the stored winding.
    """
    from workbench.services.landmarks.frame import input_frame

    try:
        m, mirrored = input_frame(head.skull_landmarks)
    except WorkbenchError:  # no Frankfort landmarks: take the head as it is
        return head, None, False
    m = np.asarray(m, float)
    if not mirrored and np.allclose(m, np.eye(4), atol=1e-12):
        return head, None, False

    def move(p: np.ndarray) -> np.ndarray:
        return np.asarray(p, float) @ m[:3, :3].T + m[:3, 3]

    moved = head.warped(move)
    if mirrored:
        moved = replace(
            moved, meshes={k: Mesh(v.vertices, v.faces[:, ::-1]) for k, v in moved.meshes.items()}
        )
    return moved, np.linalg.inv(m), mirrored


class Animator:
    """Muscle-, jaw- and gaze-driven skin of one head.

    Parameters
    ----------
    head : TemplateHead (the reference head, a template pack or a reconstruction's head)
    params : SkinParameters, optional
    compiled : use the numba kernels (default: when numba is installed); False: numpy only
    """

    def __init__(
        self,
        head: TemplateHead,
        params: SkinParameters | None = None,
        *,
        compiled: bool | None = None,
    ) -> None:
        if not head.muscles:
            raise InputError(
                head.template_id, "has no muscles to animate", "use a head built with muscles"
            )
        head, back, mirrored = _to_head_frame(head)
        self.head = head
        self._back = back
        self._mirrored = mirrored
        skin = head.skin
        x0 = skin.vertices
        n = len(x0)
        static = _mask(n, head, STATIC_REGIONS)
        bone_free = _mask(n, head, BONE_FREE_REGIONS)
        lm = head.skin_landmarks.as_dict()
        y_split = float(lm["sn"][1]) if "sn" in lm else float(np.median(x0[:, 1]))
        lower_face = x0[:, 1] < y_split
        self._cranium = MeshIndex(head.meshes["cranium"])
        self._mandible = MeshIndex(head.meshes["mandible"])
        normals = vertex_normals(skin)
        upper = _mask(n, head, ("upper_lip",))
        lower = _mask(n, head, ("lower_lip",))
        candidates: dict[str, np.ndarray] = {}
        specs = []
        for g in head.muscles:
            rows = tuple(np.asarray(r) for r in g.rows(skin))
            axis = None if g.axis is None else g.axis.evaluate(skin, normals)
            specs.append(MuscleSpec(g.code, g.kind, g.attachment, rows, axis))
            allowed = ~static
            # closed lips touch: the lower lip belongs to the jaw's orbicularis, the upper to the skull's
            # (the mouth corners are in both lip regions and may attach to both)
            if g.code == "orbicularis_oris_upper":
                allowed = allowed & ~(lower & ~upper)
            elif g.code == "orbicularis_oris_lower":
                allowed = allowed & ~(upper & ~lower)
            candidates[g.code] = allowed
        self.rig = MuscleRig(specs, x0, normals, candidates=candidates)
        self.sim = SkinSimulation(
            x0,
            skin.faces,
            cranium=self._cranium,
            mandible=self._mandible,
            simulated=~static,
            bone_free=bone_free,
            lower_face=lower_face,
            muscle_nodes=self.rig.nodes,
            muscle_weights=self.rig.weights,
            params=params,
            compiled=compiled,
        )
        self.contraction = np.zeros(len(self.rig.codes))
        self.protrusion = np.zeros(len(self.rig.codes))
        self.jaw_deg = 0.0
        self.protrusion_mm = 0.0
        self.gaze = (0.0, 0.0)
        self.lids = 0.0
        self._lid_parts = self._lid_setup(head, x0)
        # farthest eyeball point from its centre (the corneal apex) plus a lid's clearance
        eyes = head.meshes["eyes"].vertices
        if len(eyes):
            owner = np.linalg.norm(eyes[:, None] - head.eye_centres[None], axis=2).argmin(axis=1)
            apex = float(np.linalg.norm(eyes - head.eye_centres[owner], axis=1).max())
        else:
            apex = float(head.eye_radius)
        self._cornea_mm = apex + LID_CLEARANCE_MM
        # eyelid skin per eye, kept out of its globe in the shown skin (see visible)
        self._lid_skin = []
        for k, side in enumerate(("l", "r")):
            ids = [head.regions.get(f"eyelid_{p}_{side}") for p in ("upper", "lower")]
            got = [np.asarray(i, np.int64) for i in ids if i is not None]
            if got and k < len(head.eye_centres):
                self._lid_skin.append((np.concatenate(got), np.asarray(head.eye_centres[k], float)))
        self._jaw_matrix = np.eye(4)
        self._sim_jaw = np.eye(4)
        self._dirty = True
        self._rest = x0.copy()
        self._umbrella = _umbrella_operator(skin)

    def visible(self, x: np.ndarray | None = None, *, exact: bool = True) -> np.ndarray:
        """``(n, 3)`` skin shown and exported (head frame, mm): the simulated nodes ``x``
        (default: the current ones) with their displacement from rest low-passed by
        :data:`VISIBLE_SMOOTHING_PASSES` umbrella passes.

        The filtered skin is kept out of the bone by the simulation's tangent-plane
        guard and, with ``exact`` (for results), by the exact inside test on the nodes
        near bone; a live preview (``exact=False``) skips the latter (~60 ms a call).
        """
        x = self.sim.x if x is None else x
        d = np.asarray(x, float) - self._rest
        if VISIBLE_SMOOTHING_PASSES == 0:
            y = self._rest + d
            self._lids_outside_eyes(y)
            return y
        for _ in range(VISIBLE_SMOOTHING_PASSES):
            d = self._umbrella @ d
        y = self._rest + d
        self._lids_outside_eyes(y)
        # the filter must not take skin into the bone: the simulation's tangent-plane guard,
        # then the exact test on the nodes near bone (as the simulation does when it settles)
        self.sim._keep_above_bone(y)
        g = self.sim.guard_nodes
        if exact and len(g):
            for index, m in ((self._cranium, None), (self._mandible, self._jaw_matrix)):
                pts = y[g]
                r, t = (np.eye(3), np.zeros(3)) if m is None else (m[:3, :3], m[:3, 3])
                local = (pts - t) @ r
                bad = index.signed_distance(local) < 0.0
                if bad.any():
                    cl = index.closest_points(local[bad])
                    nrm = index.pseudo_normals(cl.face_ids, cl.barycentric)
                    fixed = cl.points + nrm * self.sim.params.bone_margin_mm
                    y[g[bad]] = fixed @ r.T + t
        return y

    def _lids_outside_eyes(self, y: np.ndarray) -> None:
        """Eyelid skin moved radially out of its eyeball: beyond the corneal apex in front
        (within 35° of the gaze-ahead axis), beyond the globe elsewhere.  A closing lid's
        springs shorten its arc and pull its middle into the globe, where the cornea then
        shows through the closed lid."""
        if not self.lids and not self.contraction.any():
            return
        ahead = np.cos(np.deg2rad(35.0))
        globe = float(self.head.eye_radius) + LID_CLEARANCE_MM
        for ids, centre in self._lid_skin:
            rel = y[ids] - centre
            r = np.linalg.norm(rel, axis=1)
            unit = rel / np.maximum(r, 1e-9)[:, None]
            floor = np.where(unit[:, 2] > ahead, self._cornea_mm, globe)
            inside = r < floor
            if inside.any():
                y[ids[inside]] = centre + unit[inside] * floor[inside, None]

    def _lid_setup(
        self, head: TemplateHead, x0: np.ndarray
    ) -> list[tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]]:
        """Per lid: muscle-node slots, positions about the eye centre, centre, full turn (rad)."""
        parts = []
        lm = head.skin_landmarks.as_dict()
        slot = np.full(len(x0), -1, np.int64)
        slot[self.rig.nodes] = np.arange(len(self.rig.nodes))
        for k, side in enumerate(("l", "r")):
            ps, pi = lm.get(f"ps_{side}"), lm.get(f"pi_{side}")
            up = head.regions.get(f"eyelid_upper_{side}")
            low = head.regions.get(f"eyelid_lower_{side}")
            if ps is None or pi is None or up is None or low is None:
                continue
            c = np.asarray(head.eye_centres[k], float)
            el_ps = float(np.arctan2(ps[1] - c[1], ps[2] - c[2]))
            el_pi = float(np.arctan2(pi[1] - c[1], pi[2] - c[2]))
            meet = el_pi + 0.2 * (el_ps - el_pi)
            for nodes, margin, goal in ((up, el_ps, meet), (low, el_pi, meet)):
                nodes = np.asarray(nodes, np.int64)
                nodes = nodes[slot[nodes] >= 0]
                rel = x0[nodes] - c
                el = np.arctan2(rel[:, 1], rel[:, 2])
                far = el.max() if margin > goal else el.min()  # the lid's edge away from the eye
                fade = np.clip((far - el) / (far - margin), 0.0, 1.0)
                parts.append((slot[nodes], rel, c, (margin - goal) * fade))
        return parts

    # ------------------------------------------------------------------ parameters
    @property
    def muscle_codes(self) -> tuple[str, ...]:
        return self.rig.codes

    def _check_codes(self, values: Mapping[str, float], what: str) -> None:
        unknown = [c for c in values if c not in self.rig.index]
        if unknown:
            raise InputError(
                ", ".join(unknown),
                f"is not a muscle of this head ({what})",
                "valid names: " + ", ".join(self.rig.codes),
            )

    def set_muscles(self, values: Mapping[str, float], *, reset: bool = False) -> None:
        """Contractions ``{code: c}`` with c in [0, 1] (0 relaxed, 1 fully contracted)."""
        self._check_codes(values, "--muscle")
        bad = {c: v for c, v in values.items() if not (0.0 <= float(v) <= 1.0)}
        if bad:
            raise InputError(
                ", ".join(f"{c}={v}" for c, v in bad.items()),
                "contraction must be between 0 (relaxed) and 1 (fully contracted)",
            )
        if reset:
            self.contraction[:] = 0.0
        for code, c in values.items():
            self.contraction[self.rig.index[code]] = float(c)
        self._dirty = True

    def set_protrusion(self, values: Mapping[str, float]) -> None:
        """Sphincter protrusion ``{code: a}`` with a in [-1, 1] (negative tucks the lips in)."""
        self._check_codes(values, "protrusion")
        for code, a in values.items():
            if not -1.0 <= float(a) <= 1.0:
                raise InputError(f"{code}={a}", "protrusion must be between -1 and 1")
            self.protrusion[self.rig.index[code]] = float(a)
        self._dirty = True

    def set_jaw(self, degrees: float, protrusion_mm: float = 0.0) -> None:
        """Jaw rotation about the inter-condylar axis (positive opens) and forward shift in mm."""
        lo, hi = JAW_RANGE_DEG
        if not np.isfinite(degrees) or not lo <= degrees <= hi:
            raise InputError(
                f"jaw {degrees}°", f"is outside the jaw's range {lo:g}..{hi:g}° (positive opens)"
            )
        plo, phi = PROTRUSION_RANGE_MM
        if not np.isfinite(protrusion_mm) or not plo <= protrusion_mm <= phi:
            raise InputError(
                f"jaw protrusion {protrusion_mm} mm", f"is outside {plo:g}..{phi:g} mm"
            )
        point, direction = self.head.tmj_axis
        m = axis_rotation(point, direction, np.deg2rad(degrees))
        m[:3, 3] += np.array([0.0, 0.0, protrusion_mm])
        self._jaw_matrix = m
        self.jaw_deg = float(degrees)
        self.protrusion_mm = float(protrusion_mm)
        self._dirty = True

    def set_gaze(self, yaw_deg: float, pitch_deg: float) -> None:
        """Eye rotation: yaw toward the subject's left (+), pitch up (+), in degrees."""
        for v in (yaw_deg, pitch_deg):
            if not np.isfinite(v) or abs(v) > GAZE_RANGE_DEG:
                raise InputError(f"gaze {v}°", f"is outside ±{GAZE_RANGE_DEG:g}°")
        self.gaze = (float(yaw_deg), float(pitch_deg))

    def set_lids(self, closure: float) -> None:
        """Eyelid closure 0 (open) .. 1 (closed), MEDUSA's eyelid aperture (digest §12).

        The levator palpebrae is not among the 24 muscles: the eyelid skin
        is turned about the horizontal axis through the eye centre (as
        Breton's lids are pieces of a sphere turned about its centre), the
        upper lid's margin down to 80 % of the way to the lower lid's, the
        lower lid's up the rest, fading to nothing at the lid's far edge.
        The turned positions are targets of the lid nodes' muscle springs.
        """
        if not np.isfinite(closure) or not 0.0 <= closure <= 1.0:
            raise InputError(f"lid closure {closure}", "must be between 0 (open) and 1 (closed)")
        self.lids = float(closure)
        self._dirty = True

    def set_expression(self, name_or_expression: str | Expression, weight: float = 1.0) -> None:
        """Replace all muscle, protrusion and jaw parameters with one palette expression."""
        if isinstance(name_or_expression, str):
            if name_or_expression not in EXPRESSIONS:
                raise InputError(
                    name_or_expression,
                    "is not an expression",
                    "valid names: " + ", ".join(sorted(EXPRESSIONS)),
                )
            e = EXPRESSIONS[name_or_expression]
        else:
            e = name_or_expression
        if weight != 1.0:
            e = Expression(
                {c: min(1.0, weight * v) for c, v in e.muscles.items()},
                {c: float(np.clip(weight * v, -1, 1)) for c, v in e.protrusion.items()},
                weight * e.jaw_deg,
                lids=e.lids,
            )
        muscles = {c: v for c, v in e.muscles.items() if c in self.rig.index}
        self.set_muscles(muscles, reset=True)
        self.protrusion[:] = 0.0
        self.set_protrusion({c: v for c, v in e.protrusion.items() if c in self.rig.index})
        self.set_jaw(e.jaw_deg, self.protrusion_mm)
        self.set_lids(min(1.0, weight * e.lids))

    # ------------------------------------------------------------------ simulation
    def update_muscles(self) -> None:
        """Push the current parameters into the skin's spring targets (cheap; see the benchmark)."""
        m = self._jaw_matrix
        jaw = (m[:3, :3], m[:3, 3])
        if not np.array_equal(m, self._sim_jaw):  # moving the bone anchors costs ~0.5 ms
            self.sim.set_jaw(*jaw)
            self._sim_jaw = m.copy()
        targets = self.rig.targets(self.contraction, self.protrusion, jaw)
        if self.lids > 0:
            # the closing lid slides over the cornea, which bulges ~1 mm beyond the globe
            # the lid skin rests on: its targets are kept outside the cornea (blended in
            # over the first half of the closure, so opening lids do not jump)
            ramp = min(1.0, 2.0 * self.lids)
            for local, rel, centre, turn in self._lid_parts:
                moved = _turned_down(rel, turn * self.lids * LID_GAIN)
                r = np.linalg.norm(moved, axis=1)
                want = np.maximum(r, r + ramp * (self._cornea_mm - r))
                moved *= (want / np.maximum(r, 1e-9))[:, None]
                targets[local] += moved + centre - self.sim.rest[self.rig.nodes[local]]
        self.sim.set_muscle_targets(targets)
        self._dirty = False

    def step(self, n: int = 1) -> None:
        """``n`` simulation steps of ``sim.params.time_step_s`` seconds."""
        if self._dirty:
            self.update_muscles()
        self.sim.step(n)

    def settle(self, tol_mm: float = 1e-4, max_steps: int = 4000) -> int:
        """Step until the skin is at rest, then make sure no node is inside a bone; returns steps."""
        if self._dirty:
            self.update_muscles()
        steps = self.sim.settle(tol_mm=tol_mm, max_steps=max_steps)
        self.sim.push_out_of_bone([(self._cranium, None), (self._mandible, self._jaw_matrix)])
        return steps

    def relax(self) -> int:
        """All muscles relaxed, jaw closed, then settle: the skin returns to rest."""
        self.contraction[:] = 0.0
        self.protrusion[:] = 0.0
        self.set_jaw(0.0, 0.0)
        return self.settle(tol_mm=2e-5)

    # ------------------------------------------------------------------ results
    def _out(self, points: np.ndarray) -> np.ndarray:
        if self._back is None:
            return points
        return points @ self._back[:3, :3].T + self._back[:3, 3]

    def _faces_out(self, mesh: Mesh) -> np.ndarray:
        """Triangles as stored: wound the other way for a head stored mirrored."""
        return mesh.faces[:, ::-1] if self._mirrored else mesh.faces

    def to_shown(self, points: np.ndarray) -> np.ndarray:
        """Points ``(k, 3)`` of the Frankfort head frame (:attr:`head`'s) in the frame the
        skin is shown and stored in (the head's own, mm)."""
        return self._out(np.asarray(points, float))

    def skin(self, *, exact: bool = True) -> Mesh:
        """The current skin as shown (:meth:`visible`; mm, in the head's own frame)."""
        return Mesh(self._out(self.visible(exact=exact)), self._faces_out(self.head.skin))

    def skin_in_head_frame(self) -> np.ndarray:
        """``(n, 3)`` current skin vertices as shown, in the Frankfort head frame (mm)."""
        return self.visible()

    def meshes(self) -> dict[str, Mesh]:
        """Every part in the current pose: jaw parts moved with the jaw, eyes turned by the gaze."""
        out: dict[str, Mesh] = {}
        m = self._jaw_matrix
        for part, mesh in self.head.meshes.items():
            v = mesh.vertices
            if part == "skin":
                v = self.visible()
            elif part in JAW_PARTS:
                v = v @ m[:3, :3].T + m[:3, 3]
            elif part == "eyes" and self.gaze != (0.0, 0.0):
                v = self._turned_eyes(v)
            out[part] = Mesh(self._out(np.asarray(v, float)), self._faces_out(mesh))
        return out

    def _turned_eyes(self, v: np.ndarray) -> np.ndarray:
        centres = np.asarray(self.head.eye_centres, float)
        owner = np.linalg.norm(v[:, None] - centres[None], axis=2).argmin(axis=1)
        yaw, pitch = np.deg2rad(self.gaze)
        # yaw about +y turns +z toward +x (subject's left); pitch about -x turns +z toward +y
        ry = np.array([[np.cos(yaw), 0, np.sin(yaw)], [0, 1, 0], [-np.sin(yaw), 0, np.cos(yaw)]])
        rx = np.array(
            [[1, 0, 0], [0, np.cos(pitch), np.sin(pitch)], [0, -np.sin(pitch), np.cos(pitch)]]
        )
        r = ry @ rx
        out = v.copy()
        for k, c in enumerate(centres):
            sel = owner == k
            out[sel] = (v[sel] - c) @ r.T + c
        return out


def _umbrella_operator(skin: Mesh) -> Any:
    """Sparse (n, n) operator taking each vertex half-way to its edge neighbours' mean."""
    from scipy import sparse

    f = skin.faces
    n = skin.n_vertices
    e = np.vstack([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]])
    adj = sparse.coo_matrix((np.ones(len(e)), (e[:, 0], e[:, 1])), shape=(n, n)).tocsr()
    adj = ((adj + adj.T) > 0).astype(np.float64)
    degree = np.asarray(adj.sum(axis=1)).ravel()
    mean = sparse.diags(1.0 / np.maximum(degree, 1.0)) @ adj
    return (0.5 * sparse.identity(n, format="csr") + 0.5 * mean).tocsr()


def _turned_down(rel: np.ndarray, angle: np.ndarray) -> np.ndarray:
    """Points about an eye centre turned about the x axis, lowering their elevation by ``angle``."""
    y, z = rel[:, 1], rel[:, 2]
    ca, sa = np.cos(angle), np.sin(angle)
    out = rel.copy()
    out[:, 1] = y * ca - z * sa
    out[:, 2] = z * ca + y * sa
    return out


def animate_head(
    head: TemplateHead,
    expression: str | None = None,
    muscles: Mapping[str, float] | None = None,
    jaw_deg: float | None = None,
) -> tuple[Mesh, Animator, int]:
    """Settled skin for an expression and/or explicit contractions (the ``animate`` command)."""
    anim = Animator(head)
    if expression is not None:
        anim.set_expression(expression)
    if muscles:
        anim.set_muscles(muscles)
    if jaw_deg is not None:
        anim.set_jaw(jaw_deg, anim.protrusion_mm)
    steps = anim.settle()
    return anim.skin(), anim, steps


__all__ = [
    "ACTION_UNITS",
    "EXPRESSIONS",
    "ActionUnit",
    "Animator",
    "Expression",
    "animate_head",
    "from_action_units",
    "mix",
]
