"""The six face regions of a reference head's skin (forehead, orbits, nose, cheeks, mouth, chin).

Vertex ids of the skin (head frame, mm: x to the subject's left, y up, z toward the
face); the regions every figure per region uses: validation, comparison, the tissue
model's region factors, the scan fit's figures.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from workbench.core.errors import InputError
from workbench.core.landmarks import LandmarkSet
from workbench.core.mesh import Mesh
from workbench.model.template import TemplateHead

#: the face regions, in the order every table lists them
REGION_NAMES = ("forehead", "orbits", "nose", "cheeks", "mouth", "chin")


def face_regions(head: TemplateHead) -> dict[str, np.ndarray]:
    """Skin vertex ids of the template per face region (see :func:`skin_face_regions`)."""
    return skin_face_regions(head.skin, head.regions, head.skin_landmarks)


def skin_face_regions(
    skin: Mesh, regions: Mapping[str, np.ndarray], landmarks: LandmarkSet
) -> dict[str, np.ndarray]:
    """Split the template skin's ``face`` region into six disjoint regions.

    ``regions`` are the template's labelled vertex sets (``face``, ``nose``,
    ``orbit_l/r``, ``eyelid_upper/lower_l/r``, ``perioral``, ``upper_lip``,
    ``lower_lip`` ...) and ``landmarks`` its skin landmarks, both in the head
    frame.  Each face vertex goes to the first rule that holds:

    * **orbits** — the orbit and eyelid regions of both sides;
    * **nose** — the nose region (nasion to subnasale, alae);
    * **mouth** — lips and the perioral region down to the height of
      sublabiale (``sl``, the labiomental fold);
    * **chin** — below sublabiale and no wider than the mouth corners
      (``|x| <= |x(ch)|``), including the submental skin of the face region;
    * **forehead** — above nasion (``y > y(n)``): forehead, glabella and temples;
    * **cheeks** — the rest: between the nasion and sublabiale heights
      lateral to orbits, nose and mouth (zygomatic, buccal, parotid skin),
      and the jaw lateral to the chin.

    The union of the six is the ``face`` region.
    """
    v = skin.vertices
    n = len(v)
    face = np.zeros(n, bool)
    face[np.asarray(regions["face"], int)] = True

    def members(*names: str) -> np.ndarray:
        mask = np.zeros(n, bool)
        for name in names:
            if name in regions:
                mask[np.asarray(regions[name], int)] = True
        return mask & face

    lm = landmarks.as_dict()
    try:
        y_n, y_sl = lm["n"][1], lm["sl"][1]
        half_mouth = 0.5 * abs(lm["ch_l"][0] - lm["ch_r"][0])
    except KeyError as exc:
        raise InputError(
            "template skin landmarks",
            f"missing {exc.args[0]!r} needed for the face regions",
            "the template needs n, sl, ch_l and ch_r",
        ) from exc
    left = face.copy()
    out: dict[str, np.ndarray] = {}
    orbit = members(*(f"{r}_{s}" for r in ("orbit", "eyelid_upper", "eyelid_lower") for s in "lr"))
    rules = {
        "orbits": orbit,
        "nose": members("nose"),
        "mouth": members("upper_lip", "lower_lip", "perioral") & (v[:, 1] >= y_sl),
        "chin": (v[:, 1] < y_sl) & (np.abs(v[:, 0]) <= half_mouth),
        "forehead": v[:, 1] > y_n,
        "cheeks": np.ones(n, bool),
    }
    for name, rule in rules.items():
        take = left & rule
        out[name] = np.nonzero(take)[0]
        left &= ~take
    return {name: out[name] for name in REGION_NAMES}
