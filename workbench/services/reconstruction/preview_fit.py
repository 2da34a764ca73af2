"""Interactive preview of a fitted face while a landmark or a guide is dragged.

A full fit (:func:`workbench.services.reconstruction.reconstruct.reconstruct`) plans the
dowels, computes the guides and runs the non-penetration refits: about 1.5 s
on a 100k-triangle skull.  While the user drags, the face must follow at
10 Hz or more, so the preview keeps everything of the last full fit fixed —
the head frame, the dowel directions and depths, the clearance
correspondences the refits added — and only moves the targets the dragged
thing owns:

* a skull landmark: the tip of its dowel, ``origin + depth · direction``
  with the dowel's planned direction and depth and the new origin;
* a guide: the coordinate(s) it fixes of the skin landmarks it affects
  (a vline sets x, an hline y, a lateral point (y, z); head frame).

The same regularised landmark warp as the full fit is then re-solved
(``(k+4)²`` system, k ≈ 300) and applied to the reference skin only (about
5 000 vertices): a few milliseconds.  The lids are then rested on the last
fit's eyeballs as the fit rests them
(:func:`~workbench.services.reconstruction.lids.lids_on_globes`).
Because the warp is re-solved with the last fit's correspondences, a preview
of an unchanged state reproduces the fitted skin exactly.  The full fit runs again when the drag ends.

Units mm.  Landmark positions in and skin vertices out are in the
specimen's **input frame** (the skull file's coordinates); internally the
head frame of the fit (x to the subject's left, y up, z forward, Frankfort
Horizontal at y = 0).
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass, field

import numpy as np

from workbench.core.frame import apply_transform
from workbench.core.mesh import Mesh
from workbench.core.tps import fit_warp
from workbench.model.template import TemplateHead
from workbench.services.guides.classic import AXES, Guide
from workbench.services.reconstruction.lids import lids_on_globes
from workbench.services.reconstruction.reconstruct import SMOOTHING, Reconstruction


@dataclass
class PreviewFit:
    """A fit whose targets can be moved and re-solved quickly (see the module docstring).

    Build it with :meth:`from_fit`; :meth:`move_landmark` / :meth:`move_guide`
    change targets and :meth:`skin` returns the previewed skin.
    """

    sources: np.ndarray  # (k, 3) reference skin points, head frame
    targets: np.ndarray  # (k, 3) current targets, head frame (edited in place)
    labels: tuple[str, ...]
    skin_vertices: np.ndarray  # (n, 3) the skin the last warp applies to, head frame
    input_to_head: np.ndarray  # (4, 4)
    dowels: dict[str, tuple[float, np.ndarray]]  # skull code → (depth mm, unit direction)
    _rows: dict[str, np.ndarray] = field(default_factory=dict)
    smoothing: np.ndarray | None = None  # (k,) λ per correspondence (mm); None = SMOOTHING
    eyes: Mesh | None = None  # the last fit's eyeballs (head frame), the lids rest on

    @classmethod
    def from_fit(cls, recon: Reconstruction, reference: TemplateHead) -> PreviewFit:
        """The preview of ``recon``, a fit of ``reference`` (the unwarped head)."""
        if len(recon.labels) != len(recon.sources):
            raise ValueError("the fit carries no correspondence labels; fit it again")
        depths = dict(recon.dowel_depths)
        dowels = {
            d.code: (float(depths.get(d.code, d.depth_mm)), np.asarray(d.direction, float))
            for d in recon.plan.dowels
            if not d.excluded
        }
        base = recon.base_skin if recon.base_skin is not None else reference.skin.vertices
        rows: dict[str, list[int]] = {}
        for i, label in enumerate(recon.labels):
            rows.setdefault(label, []).append(i)
        return cls(
            np.array(recon.sources, float),
            np.array(recon.targets, float),
            tuple(recon.labels),
            np.array(base, float),
            np.array(recon.input_to_head, float),
            dowels,
            {k: np.array(v, dtype=np.int64) for k, v in rows.items()},
            None if recon.smoothing is None else np.array(recon.smoothing, float),
            recon.head.meshes.get("eyes"),
        )

    # ------------------------------------------------------------ edits
    def move_landmark(self, code: str, position_input: Iterable[float]) -> bool:
        """Move skull landmark ``code`` (input frame, mm); False if it has no dowel here."""
        rows = self._rows.get(f"dowel:{code}")
        if rows is None or code not in self.dowels:
            return False
        depth, direction = self.dowels[code]
        origin = apply_transform(self.input_to_head, np.asarray(position_input, float)[None])[0]
        self.targets[rows] = origin + depth * direction
        self._release_anchors(self.sources[rows])
        return True

    def _release_anchors(self, points: np.ndarray) -> None:
        """Anchors near a dragged correspondence stop holding the skin (they would fight it)."""
        from workbench.services.reconstruction.reconstruct import ANCHOR_CLEARANCE_MM

        anchor = np.array([lab == "anchor" for lab in self.labels])
        if not anchor.any():
            return
        d = np.min(np.linalg.norm(self.sources[:, None] - np.asarray(points)[None], axis=2), axis=1)
        drop = anchor & (d < ANCHOR_CLEARANCE_MM)
        if drop.any():
            keep = ~drop
            self.sources, self.targets = self.sources[keep], self.targets[keep]
            if self.smoothing is not None:
                self.smoothing = self.smoothing[keep]
            self.labels = tuple(lab for lab, k in zip(self.labels, keep, strict=True) if k)
            rows: dict[str, list[int]] = {}
            for i, label in enumerate(self.labels):
                rows.setdefault(label, []).append(i)
            self._rows = {k: np.array(v, dtype=np.int64) for k, v in rows.items()}

    def move_guide(self, guide: Guide) -> bool:
        """Apply ``guide`` (its value, head frame mm) to the skin landmarks it affects.

        Returns False when none of them is a correspondence of this fit
        (the guide was off or rejected when the fit ran: the full fit decides).
        """
        if not guide.enabled:
            return False
        moved = False
        for code in guide.affects:
            rows = self._rows.get(f"guide:{code}")
            if rows is None:
                continue
            for axis, value in zip(AXES[guide.kind], guide.value, strict=True):
                self.targets[rows, axis] = float(value)
            self._release_anchors(self.sources[rows])
            moved = True
        return moved

    # ------------------------------------------------------------ result
    def skin_head(self) -> np.ndarray:
        """The previewed skin vertices in the head frame (mm)."""
        lam = SMOOTHING if self.smoothing is None else self.smoothing
        warp = fit_warp(self.sources, self.targets, smoothing=lam)
        return lids_on_globes(warp(self.skin_vertices, workers=1), self.eyes)[0]

    def to_input(self, points_head: np.ndarray) -> np.ndarray:
        """Head-frame points (mm) → the input frame."""
        return apply_transform(np.linalg.inv(self.input_to_head), points_head)

    def skin(self) -> np.ndarray:
        """The previewed skin vertices in the input frame (mm), same order as the fit's face."""
        return self.to_input(self.skin_head())
