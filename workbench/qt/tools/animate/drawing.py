"""How the animate tool draws: the skin and the parts under it, moved in place per frame.

:class:`AnimateDrawing` is mixed into :class:`~workbench.qt.tools.animate.tool.AnimateTool`
(whose ``__init__`` sets the attributes it names).  The head is drawn once; after that a
frame moves the points (and normals) of the existing actors, never re-adds one.
:func:`load_animator` is the worker's part (no Qt, no VTK).

When the head is the case's reconstruction and the case chose hair, brows or a beard
(the Appearance dock), they are drawn on it and move with every frame: the strands are
tied to the skin (:func:`workbench.services.grooming.hair_meshes` on the frame's skin,
every :data:`HAIR_STRIDE`-th scalp strand; grown in a worker the first time).  They are
artistic additions, not evidence.

Units mm, the head's own frame (Frankfort: x to the subject's left, y up, z toward the
face).  How the head looks is :mod:`workbench.render.visuals.heads`; this part decides
when it is drawn, which parts are visible, and removes the actors.
"""

from __future__ import annotations

from dataclasses import replace
from typing import TYPE_CHECKING, Any

import numpy as np

from workbench.qt.tools.common import HairGrower
from workbench.render.visuals import heads, update

if TYPE_CHECKING:
    from workbench.model.appearance import Appearance
    from workbench.qt.panels.animate_panel import AnimatePanel
    from workbench.qt.scene import SceneView
    from workbench.services.animation.animator import Animator

#: parts drawn under the skin (the "Skull and teeth" check box); the eyes are always shown
INNER_PARTS = ("cranium", "mandible", "upper_teeth", "lower_teeth")
ALWAYS_SHOWN = ("eyes",)
#: every n-th strand of the scalp hair is drawn (each frame rebuilds the ribbons: ~60 ms for
#: short hair, brows and a beard at 2, twice that at 1)
HAIR_STRIDE = 2
#: parts moved with the jaw, and the parts the gaze turns
JAW_MOVED = ("mandible", "lower_teeth", "tongue")
GAZE_MOVED = ("eyes",)


def load_animator(sex: str) -> Animator:
    """The reference head of ``sex`` ready to animate (worker side: no Qt, no VTK)."""
    from workbench.services.animation.animator import Animator
    from workbench.services.templates.cache import reference_head

    return Animator(reference_head(sex))


class AnimateDrawing:
    """The animate tool's actors (mixed into the tool, whose ``__init__`` sets these)."""

    panel: AnimatePanel
    scene: SceneView
    plotter: Any
    animator: Animator | None
    active: bool
    _actors: dict[str, Any]
    _points: np.ndarray | None
    _faces: dict[str, np.ndarray]
    _vf: dict[str, Any]
    _jaw_drawn: float
    _gaze_drawn: tuple[float, float]
    sex: str
    host: Any
    runner: Any
    _hair_grower: HairGrower | None = None

    def draw(self) -> None:
        """(Re)draw the skin and the inner parts of the loaded head."""
        self.clear()
        anim = self.animator
        if anim is None:
            return
        meshes = anim.meshes()
        skin = meshes["skin"]
        self._actors["skin"] = heads.add_animated_skin(self.plotter, skin)
        self._actors["skin"].SetVisibility(self.active)
        self._faces = {part: mesh.faces for part, mesh in meshes.items()}
        # vertex-face incidence of each part, kept for the per-frame normals
        self._vf = {part: mesh.vertex_faces_matrix for part, mesh in meshes.items()}
        self._points = skin.vertices.copy()
        for part in INNER_PARTS + ALWAYS_SHOWN:
            if part not in meshes:
                continue
            actor = heads.add_animated_part(self.plotter, part, meshes[part], anim)
            shown = part in ALWAYS_SHOWN or self.panel.bones.isChecked()
            actor.SetVisibility(shown and self.active)
            self._actors[part] = actor
        self._jaw_drawn = anim.jaw_deg
        self._gaze_drawn = anim.gaze
        self._show_inner(self.active and self.panel.bones.isChecked())
        self.draw_hair()

    # ------------------------------------------------------------ hair
    def hair_look(self) -> Appearance | None:
        """The case's appearance when the head is its reconstruction and hair was chosen."""
        document = getattr(self.host, "document", None)
        look = document.case.appearance if document is not None else None
        if self.sex != "reconstruction" or look is None or not look.grooming:
            return None
        return look

    def draw_hair(self) -> None:
        """The case's hair on the animated head as it is now (none for other heads)."""
        from workbench.render.visuals.face import add_hair

        for key in [k for k in self._actors if k.startswith("hair_")]:
            self.plotter.remove_actor(self._actors.pop(key), render=False)
        anim, look = self.animator, self.hair_look()
        if anim is None or look is None or self.scene.closed:
            return
        if self._hair_grower is None:
            self._hair_grower = HairGrower(self.runner, "animate_hair", self.draw_hair)
        if not self._hair_grower.ready(anim.head, look):
            return
        for piece in self._hair_pieces(anim, look):
            name = f"hair_{piece.kind}"
            actor = add_hair(self.plotter, piece.mesh, piece.srgb, piece.normals, name=name)
            actor.SetVisibility(self.active)
            self._actors[name] = actor
        self.scene.request_render()

    def _hair_pieces(self, anim: Animator, look: Appearance) -> list[Any]:
        """The pieces on the animator's current skin, in the shown frame."""
        from workbench.core.mesh import Mesh
        from workbench.services.grooming import hair_meshes

        pieces = hair_meshes(anim.head, look, anim.skin_in_head_frame(), stride=HAIR_STRIDE)
        rotation = anim.to_shown(np.eye(3)) - anim.to_shown(np.zeros((1, 3)))
        return [
            replace(
                p,
                mesh=Mesh(anim.to_shown(p.mesh.vertices), p.mesh.faces),
                normals=p.normals @ rotation,
            )
            for p in pieces
        ]

    def _move_hair(self) -> None:
        """Move the hair's ribbons to the animator's current skin (points in place)."""
        anim, look = self.animator, self.hair_look()
        if anim is None or look is None or not any(k.startswith("hair_") for k in self._actors):
            return
        for piece in self._hair_pieces(anim, look):
            actor = self._actors.get(f"hair_{piece.kind}")
            if actor is not None:
                update.set_points_and_normals(actor, piece.mesh.vertices, piece.normals)

    def actors(self) -> dict[str, Any]:
        """``{part: actor}`` drawn by this tool (tests)."""
        return dict(self._actors)

    def clear(self) -> None:
        for actor in self._actors.values():
            self.plotter.remove_actor(actor, render=False)
        self._actors.clear()
        self._points = None
        self.scene.request_render()

    def _show_inner(self, on: bool) -> None:
        for part in INNER_PARTS:
            actor = self._actors.get(part)
            if actor is not None:
                actor.SetVisibility(bool(on))
        skin = self._actors.get("skin")
        if skin is not None:  # the bones show through a translucent skin
            heads.set_see_through(skin, bool(on))
        self.scene.request_render()

    def _move_skin(self, points: np.ndarray) -> None:
        actor = self._actors.get("skin")
        anim = self.animator
        if actor is None or anim is None:
            return
        update.set_surface_points(actor, points, self._faces["skin"], self._vf.get("skin"))
        self._points = points
        self._move_hair()

    def _move_inner(self) -> None:
        """Move the jaw's parts and the eyes to the animator's pose (points in place)."""
        anim = self.animator
        if anim is None:
            return
        for part, points in inner_points(anim, JAW_MOVED + GAZE_MOVED).items():
            actor = self._actors.get(part)
            if actor is not None:
                update.set_surface_points(actor, points, self._faces[part], self._vf.get(part))
        self._jaw_drawn = anim.jaw_deg
        self._gaze_drawn = anim.gaze
        self.scene.request_render()

    def _move_inner_if_moved(self) -> None:
        anim = self.animator
        if anim is not None and (anim.jaw_deg != self._jaw_drawn or anim.gaze != self._gaze_drawn):
            self._move_inner()

    def drawn_points(self, part: str) -> np.ndarray:
        """``(n, 3)`` vertices (mm) of a drawn part as the 3D view has them (tests)."""
        return update.drawn_points(self._actors[part].GetMapper().GetInput())

    def reset_camera(self) -> None:
        """Look at the face from the front (the head frame: +z toward the face, +y up)."""
        anim = self.animator
        if anim is None:
            return
        v = anim.skin().vertices
        lm = anim.head.skin_landmarks.as_dict()
        face = v[v[:, 2] > np.percentile(v[:, 2], 40)]  # the front of the head
        lo, hi = face.min(axis=0), face.max(axis=0)
        centre = (lo + hi) / 2
        if "prn" in lm and "gn" in lm and "g" in lm:  # between brow and chin
            centre[1] = (float(lm["g"][1]) + float(lm["gn"][1])) / 2
        renderer = self.plotter.renderer
        camera = renderer.GetActiveCamera()
        camera.SetFocalPoint(*centre)
        camera.SetPosition(*(centre + np.array([0.0, 0.0, 600.0])))
        camera.SetViewUp(0.0, 1.0, 0.0)
        renderer.ResetCamera(*np.column_stack([lo, hi]).ravel())
        camera.Zoom(1.5)
        renderer.ResetCameraClippingRange()
        self.scene.request_render()


def inner_points(anim: Animator, parts: tuple[str, ...]) -> dict[str, np.ndarray]:
    """``{part: (n, 3)}`` vertices (mm, the head's own frame) of the jaw's parts and the
    eyes in the animator's current pose: :meth:`Animator.meshes` without its skin.

    ``meshes()`` also computes the exact skin (~50 ms on the reference head),
    too slow for every frame of a track whose jaw or gaze moves; this takes the
    same transforms (the animator's jaw matrix, its eye turn and its map back to
    the stored frame).  ``tests/qt/test_qt_animate.py`` checks it against
    ``meshes()``.
    """
    from workbench.services.registration.jaw import JAW_PARTS

    m = anim._jaw_matrix
    out: dict[str, np.ndarray] = {}
    for part in parts:
        mesh = anim.head.meshes.get(part)
        if mesh is None:
            continue
        v = np.asarray(mesh.vertices, float)
        if part in JAW_PARTS:
            v = v @ m[:3, :3].T + m[:3, 3]
        elif part == "eyes" and anim.gaze != (0.0, 0.0):
            v = anim._turned_eyes(v)
        out[part] = anim._out(v)
    return out
