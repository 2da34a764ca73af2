"""How the age tool draws: the source head and the aged one, side by side or overlaid.

:class:`AgeDrawing` is the drawing half of :class:`~workbench.qt.tools.age.tool.AgeTool`
(which it is mixed into): the tool decides which computed age is shown, this part puts
the heads, their eyes (painted with an iris and pupil) and the caption in the 3D view.
The aged skin has the source's vertices and triangles, so it is built once and its
points are moved in place for each age; so are the aged eyes, drawn from the source's.

When the source is the case's reconstruction and the case chose hair, brows or
a beard (the Appearance dock), they are drawn on both heads: the same strands,
tied to the skin, so the aged head shows them on its grown or aged face
(:func:`workbench.services.grooming.hair_meshes` with the aged skin; grown in
a worker the first time).  They are artistic additions, not evidence.

Units mm, each head in its own Frankfort frame; the actors are the tool's own, not
:data:`workbench.qt.scene.LAYERS`.  How the heads look is
:mod:`workbench.render.visuals.heads`; this part decides when they are drawn and
removes them.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np

from workbench.qt.tools.common import HairGrower
from workbench.render.visuals import heads, update

if TYPE_CHECKING:
    from workbench.model.appearance import Appearance
    from workbench.qt.panels.age_panel import AgePanel
    from workbench.qt.scene import SceneView
    from workbench.qt.tools.age.work import AgeSettings, AgeStep, SourceHead

#: space between the two heads side by side (mm)
GAP_MM = 40.0
#: every n-th strand of the scalp hair is drawn in the dock (1: all; the heads here have no
#: painted scalp under the hair, so a thinned preview would show bare skin between strands)
HAIR_STRIDE = 1


class AgeDrawing:
    """The age tool's actors (mixed into the tool, whose ``__init__`` sets these)."""

    panel: AgePanel
    scene: SceneView
    plotter: Any
    source: SourceHead | None
    cache: dict[int, AgeStep]
    shown_age: int | None
    active: bool
    camera_pending: bool
    _actors: dict[str, Any]
    _caption: Any
    runner: Any
    document: Any
    _hair_grower: HairGrower | None = None

    def settings(self) -> AgeSettings:
        raise NotImplementedError  # the tool's: the panel's choices

    @property
    def step(self) -> AgeStep | None:
        """The computed age drawn now."""
        return None if self.shown_age is None else self.cache.get(self.shown_age)

    def _mode_changed(self, _mode: str) -> None:
        self.draw()
        self.reset_camera()

    def actors(self) -> dict[str, Any]:
        """``{"before" | "after" | "before_eyes" | "after_eyes": actor}`` drawn by this tool
        (tests); the aged eyes only while an age is shown."""
        return dict(self._actors)

    def offset(self) -> np.ndarray:
        """Where the source head is drawn relative to its frame (mm): side by side, to −x."""
        if self.source is None or self.panel.mode() != "side":
            return np.zeros(3)
        span = float(np.ptp(self.source.head.skin.vertices[:, 0]))
        return np.array([-(span + GAP_MM), 0.0, 0.0])

    def clear(self) -> None:
        for actor in self._actors.values():
            self.plotter.remove_actor(actor, render=False)
        self._actors.clear()
        if self._caption is not None:
            self.plotter.remove_actor(self._caption, render=False)
            self._caption = None
        self.scene.request_render()

    def draw(self) -> None:
        """(Re)draw the source head and the shown aged head for the panel's mode."""
        self.clear()
        source = self.source
        if source is None or self.scene.closed:
            return
        overlay = self.panel.mode() == "overlay"
        skin = source.head.skin.transformed(_shift(self.offset()))
        self._actors["before"] = heads.add_age_source(self.plotter, skin, overlay=overlay)
        painted = heads.head_eyes(source.head)
        if painted is not None and not overlay:  # (in the overlay the aged eyes are shown)
            self._actors["before_eyes"] = heads.add_age_eyes(
                self.plotter, painted, name="age_before_eyes", offset=self.offset()
            )
        # drawn while the dock is behind another (a reopened case's study): shown with the dock
        for key in ("before", "before_eyes"):
            if key in self._actors:
                self._actors[key].SetVisibility(self.active)
        self._caption = heads.add_age_caption(self.plotter)
        self._draw_after(rebuild=True)

    def _draw_after(self, rebuild: bool = False) -> None:
        """The aged skin of :attr:`step`: built once, then its points moved in place."""
        source, step = self.source, self.step
        if source is None or "before" not in self._actors or self.scene.closed:
            return
        overlay = self.panel.mode() == "overlay"
        actor = self._actors.get("after")
        if rebuild or actor is None:
            if actor is not None:
                self.plotter.remove_actor(actor, render=False)
            actor = heads.add_aged_skin(self.plotter, source.head.skin, overlay=overlay)
            self._actors["after"] = actor
        if step is not None:
            heads.show_aged(
                actor,
                step.result.head.skin.vertices,
                step.normals,
                step.distance,
                overlay=overlay,
            )
        actor.SetVisibility(self.active and step is not None)
        self._draw_aged_eyes(rebuild)
        self._draw_hair()
        self._update_caption()
        self.scene.request_render()

    # ------------------------------------------------------------ hair
    def hair_look(self) -> Appearance | None:
        """The case's appearance when the source is its reconstruction and hair was chosen."""
        source, document = self.source, self.document
        look = document.case.appearance if document is not None else None
        if source is None or source.key != "fit" or look is None or not look.grooming:
            return None
        return look

    def _draw_hair(self) -> None:
        """The case's hair on the source head (not in the overlay) and the aged head."""
        from workbench.render.visuals.face import add_hair
        from workbench.services.grooming import hair_meshes

        for key in [k for k in self._actors if "_hair_" in k]:
            self.plotter.remove_actor(self._actors.pop(key), render=False)
        source, look, step = self.source, self.hair_look(), self.step
        if source is None or look is None or self.scene.closed:
            return
        head = source.head
        if self._hair_grower is None:
            self._hair_grower = HairGrower(self.runner, "age_hair", self._hair_grown)
        if not self._hair_grower.ready(head, look):
            return
        skins: dict[str, np.ndarray] = {}
        if self.panel.mode() != "overlay":
            skins["before"] = head.skin.vertices + self.offset()
        if step is not None:
            skins["after"] = step.result.head.skin.vertices
        for which, vertices in skins.items():
            for piece in hair_meshes(head, look, vertices, stride=HAIR_STRIDE):
                name = f"{which}_hair_{piece.kind}"
                actor = add_hair(self.plotter, piece.mesh, piece.srgb, piece.normals, name=name)
                actor.SetVisibility(self.active)
                self._actors[name] = actor

    def _hair_grown(self) -> None:
        self._draw_hair()
        self.scene.request_render()

    def _draw_aged_eyes(self, rebuild: bool) -> None:
        """The aged head's eyes: drawn from the source's painted eyes once, then moved in
        place to each age's globes; none while no age is shown (the tool shows every
        actor it holds with the dock)."""
        source, step = self.source, self.step
        actor = self._actors.get("after_eyes")
        painted = None if source is None else heads.head_eyes(source.head)
        if actor is not None and (rebuild or step is None or painted is None):
            self.plotter.remove_actor(self._actors.pop("after_eyes"), render=False)
            actor = None
        if step is None or painted is None or "eyes" not in step.result.head.meshes:
            return
        if actor is None:
            actor = heads.add_age_eyes(self.plotter, painted, name="age_after_eyes")
            self._actors["after_eyes"] = actor
        heads.show_aged_eyes(actor, painted, step.result.head)
        actor.SetVisibility(self.active)

    def _update_caption(self) -> None:
        if self._caption is None:
            return
        s = self.settings()
        shown = "–" if self.shown_age is None else f"{self.shown_age} y"
        if self.panel.mode() == "side":
            text = f"left: {s.from_age:g} y (source)   right: {shown} (aged)"
        else:
            text = f"{shown} (coloured: displacement from {s.from_age:g} y, mm); source translucent"
        heads.set_caption(self._caption, text)
        self._caption.SetVisibility(self.active)

    def drawn_points(self, which: str) -> np.ndarray:
        """The drawn points of ``which`` (a key of :meth:`actors`; mm; tests)."""
        return update.drawn_points(update.mapper_dataset(self._actors[which]))

    def reset_camera(self) -> None:
        """Look at both heads from the front (+z toward the face, +y up).

        Only while the dock is in front: the main view belongs to the case's layers
        otherwise (the camera is set when the dock comes to the front).
        """
        source = self.source
        self.camera_pending = not self.active
        if source is None or self.scene.closed or not self.active:
            return
        v = source.head.skin.vertices
        lo = np.minimum(v.min(axis=0), v.min(axis=0) + self.offset())
        hi = np.maximum(v.max(axis=0), v.max(axis=0) + self.offset())
        centre = (lo + hi) / 2
        renderer = self.plotter.renderer
        camera = renderer.GetActiveCamera()
        camera.SetFocalPoint(*centre)
        camera.SetPosition(*(centre + np.array([0.0, 0.0, 800.0])))
        camera.SetViewUp(0.0, 1.0, 0.0)
        renderer.ResetCamera(*np.column_stack([lo, hi]).ravel())
        camera.Zoom(1.3 if self.panel.mode() == "side" else 1.05)
        renderer.ResetCameraClippingRange()
        self.scene.request_render()


def _shift(offset: np.ndarray) -> np.ndarray:
    m = np.eye(4)
    m[:3, 3] = offset
    return m
