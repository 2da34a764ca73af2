"""One handedness in every view, and the letters on screen that say which side is which.

The convention
--------------
Every view and picture of the workbench shows the subject as an observer
facing them sees them, as a photograph does and as forensic and
anthropometric practice expects: in a frontal view the subject's **right is
on the viewer's left**.  VTK draws any frame as a right-handed one, so a
frame that is a *mirror image* of the subject would show them the other way
round.  That happens when a skull file's axes are left-handed (the VTK headsq
CT, ``space: 3D-left-handed``), which the workbench learns from the
landmarks' left/right labels or from the file's known anatomy
(``mirrored_input``; the fit's head frame then includes a reflection).  Such a
view is shown reflected — the display only: the data, the points picked, the
landmarks and every file written stay in the file's own coordinates.

:class:`Anatomy` holds the subject's anterior, superior and left directions
in a drawing's frame (unit vectors, no units) and says whether that frame is
a mirror image (:attr:`Anatomy.mirrored`).  :class:`DisplayMirror` reflects
what a renderer shows, in one of two ways:

* :meth:`DisplayMirror.reflect_world` — the interactive views: the camera's
  model transform reflects the scene across a plane (the midsagittal plane
  through the view's centre).  The renderer's world ↔ display conversions
  (picking, dragging, labels) include it, and turning the view with the
  mouse works as usual;
* :meth:`DisplayMirror.flip_screen` — still pictures: the picture is flipped
  left to right (the camera's view transform), text overlays stay readable.

Either reverses the winding of every triangle on screen; OpenGL's front face
is switched to clockwise while that renderer draws (else VTK would light the
back of every surface).

:func:`edge_letters` names the subject's side that lies toward each edge of a
view (R/L, S/I, A/P) from the camera; :class:`EdgeLetters` keeps four small
letters at the edges of a live view up to date, :func:`add_edge_letters` puts
them on a still picture.  This module may import numpy and VTK, never Qt.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import sys
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from functools import lru_cache
from typing import Any

import numpy as np

#: the four edges of a view: (screen direction, normalised viewport position, justification)
EDGES = {
    "left": ((-1.0, 0.0), (0.012, 0.5), ("left", "centered")),
    "right": ((1.0, 0.0), (0.988, 0.5), ("right", "centered")),
    "top": ((0.0, 1.0), (0.5, 0.985), ("centered", "top")),
    "bottom": ((0.0, -1.0), (0.5, 0.015), ("centered", "bottom")),
}
#: a side's letter is shown at an edge when its direction is within ~67° of the edge's
SHOWN_COS = 0.38
#: OpenGL's front-face names
_GL_CW, _GL_CCW = 0x0900, 0x0901


def _unit(v: Sequence[float] | np.ndarray) -> np.ndarray:
    a = np.asarray(v, float).reshape(3)
    n = float(np.linalg.norm(a))
    if not np.isfinite(n) or n < 1e-12:
        raise ValueError("a direction of zero length")
    return a / n


@dataclass(frozen=True)
class Anatomy:
    """The subject's anterior, superior and left directions in one frame (unit vectors).

    Build it with :meth:`of` (any three directions, made orthonormal, the
    sign of ``left`` kept) or :meth:`from_head_frame`.  In a frame that shows
    the subject as they are, (left, superior, anterior) is right-handed, as
    the head frame's (x, y, z) is; :attr:`mirrored` says it is not.
    """

    anterior: np.ndarray
    superior: np.ndarray
    left: np.ndarray

    @classmethod
    def of(
        cls,
        anterior: Sequence[float] | np.ndarray,
        superior: Sequence[float] | np.ndarray,
        left: Sequence[float] | np.ndarray | None = None,
    ) -> Anatomy:
        """From a face and an up direction; without ``left`` the frame is taken as unmirrored."""
        a = _unit(anterior)
        s = _unit(np.asarray(superior, float) - a * float(np.dot(superior, a)))
        lateral = np.cross(s, a)  # the subject's left in an unmirrored frame
        if left is not None and float(np.dot(left, lateral)) < 0:
            lateral = -lateral
        return cls(a, s, lateral)

    @classmethod
    def from_head_frame(cls, input_to_head: np.ndarray) -> Anatomy:
        """From a 4x4 input → head frame map (a reflection when the input is mirrored)."""
        back = np.linalg.inv(np.asarray(input_to_head, float)[:3, :3])
        return cls.of(back @ [0.0, 0.0, 1.0], back @ [0.0, 1.0, 0.0], back @ [1.0, 0.0, 0.0])

    @property
    def mirrored(self) -> bool:
        """True when this frame is a mirror image of the subject (left-handed anatomy)."""
        return float(np.dot(np.cross(self.left, self.superior), self.anterior)) < 0.0

    @property
    def right(self) -> np.ndarray:
        return -self.left

    def shown(self) -> Anatomy:
        """The anatomy as :meth:`DisplayMirror.reflect_world` across its midsagittal plane
        shows it (left reversed when mirrored): never mirrored."""
        return Anatomy(self.anterior, self.superior, -self.left) if self.mirrored else self


#: the head frame's anatomy: x to the subject's left, y up, z forward
HEAD = Anatomy(np.array([0.0, 0.0, 1.0]), np.array([0.0, 1.0, 0.0]), np.array([1.0, 0.0, 0.0]))


def reflection(
    point: Sequence[float] | np.ndarray, normal: Sequence[float] | np.ndarray
) -> np.ndarray:
    """The 4x4 reflection across the plane through ``point`` (mm) normal to ``normal``."""
    n = _unit(normal)
    m = np.eye(4)
    m[:3, :3] -= 2.0 * np.outer(n, n)
    m[:3, 3] = 2.0 * float(np.dot(np.asarray(point, float), n)) * n
    return m


def edge_letters(model_view: np.ndarray, anatomy: Anatomy) -> dict[str, str]:
    """``{edge: letters}``: the subject's sides that lie toward each edge of a view.

    ``model_view`` is the camera's 4x4 model-view matrix (world → eye, any
    reflections of the display included); ``anatomy`` the subject's
    directions in world coordinates.  An edge gets the letter (R, L, S, I, A,
    P) of each side within about 67° of it, the nearest first ("L", "LP"),
    or "" when none is.
    """
    rot = np.asarray(model_view, float)[:3, :3]
    sides = {
        "L": anatomy.left,
        "R": -anatomy.left,
        "S": anatomy.superior,
        "I": -anatomy.superior,
        "A": anatomy.anterior,
        "P": -anatomy.anterior,
    }
    eye = {k: rot @ v / max(float(np.linalg.norm(rot @ v)), 1e-12) for k, v in sides.items()}
    out = {}
    for edge, ((dx, dy), _at, _just) in EDGES.items():
        # nearest first; at a tie (a three-quarter view) R/L before S/I before A/P
        near = sorted(
            (
                (round(float(dx * e[0] + dy * e[1]), 2), -i, k)
                for i, (k, e) in enumerate(eye.items())
            ),
            reverse=True,
        )
        out[edge] = "".join(k for cos, _i, k in near[:2] if cos > SHOWN_COS)
    return out


def _matrix(camera: Any) -> np.ndarray:
    m = camera.GetModelViewTransformMatrix()
    return np.array([[m.GetElement(i, j) for j in range(4)] for i in range(4)])


#: the letters of the live views: light grey on a translucent dark box (readable over bone
#: and skin)
LIVE_COLOUR, LIVE_BOX = (0.88, 0.90, 0.93), (0.10, 0.11, 0.13)
#: the letters of the report pictures: dark grey on the white background, no box
PICTURE_COLOUR = (0.30, 0.30, 0.30)


def _text_actor(edge: str, colour: Sequence[float], size: int, box: Sequence[float] | None) -> Any:
    from vtkmodules.vtkRenderingCore import vtkTextActor

    _d, (x, y), (horizontal, vertical) = EDGES[edge]
    actor = vtkTextActor()
    actor.GetPositionCoordinate().SetCoordinateSystemToNormalizedViewport()
    actor.SetPosition(x, y)
    prop = actor.GetTextProperty()
    prop.SetFontSize(size)
    prop.SetBold(True)
    prop.SetColor(*colour)
    if box is not None:
        prop.SetBackgroundColor(*box)
        prop.SetBackgroundOpacity(0.55)
    getattr(prop, f"SetJustificationTo{horizontal.capitalize()}")()
    getattr(prop, f"SetVerticalJustificationTo{vertical.capitalize()}")()
    actor.SetPickable(False)
    return actor


def add_edge_letters(
    renderer: Any, anatomy: Anatomy, edges: Sequence[str] = ("left", "right"), size: int = 14
) -> list[Any]:
    """Letters at ``edges`` of a still picture, from the renderer's camera as it is now
    (:data:`PICTURE_COLOUR`, ``size`` in points; the sides only by default: the top and
    bottom of a report picture hold its title and bars)."""
    letters = edge_letters(_matrix(renderer.GetActiveCamera()), anatomy)
    actors = []
    for edge, text in letters.items():
        if text and edge in edges:
            actor = _text_actor(edge, PICTURE_COLOUR, size, None)
            actor.SetInput(text)
            renderer.AddViewProp(actor)
            actors.append(actor)
    return actors


class EdgeLetters:
    """Four small letters at the edges of a live view, updated before each of its renders.

    ``when()`` (optional) says whether they apply to what the view shows now
    (the main view lends its camera to tools drawing other frames); with no
    anatomy (:meth:`set_anatomy` None) or ``when()`` false they are hidden.
    The actors are the renderer's own (not named in pyvista); one taken away
    by ``plotter.clear_actors()`` is put back before the next render.
    """

    def __init__(
        self, renderer: Any, size: int = 14, when: Callable[[], bool] | None = None
    ) -> None:
        self.renderer = renderer
        self.anatomy: Anatomy | None = None
        self.when = when
        self.actors = {edge: _text_actor(edge, LIVE_COLOUR, size, LIVE_BOX) for edge in EDGES}
        for actor in self.actors.values():
            actor.SetVisibility(False)
            renderer.AddViewProp(actor)
        self._tag: int | None = renderer.AddObserver("StartEvent", self._update)

    def set_anatomy(self, anatomy: Anatomy | None) -> None:
        """The subject's directions in the view's world coordinates (None: no letters)."""
        self.anatomy = anatomy
        self._update()

    @property
    def shown(self) -> dict[str, str]:
        """``{edge: letters}`` as last drawn ("" where hidden)."""
        return {
            edge: (actor.GetInput() or "") if actor.GetVisibility() else ""
            for edge, actor in self.actors.items()
        }

    def _update(self, *_args: Any) -> None:
        on = self.anatomy is not None and (self.when is None or self.when())
        letters = (
            edge_letters(_matrix(self.renderer.GetActiveCamera()), self.anatomy)
            if on and self.anatomy is not None
            else {}
        )
        for edge, actor in self.actors.items():
            if not self.renderer.HasViewProp(actor):  # pyvista's clear_actors takes every prop
                self.renderer.AddViewProp(actor)
            text = letters.get(edge, "")
            if (actor.GetInput() or "") != text:
                actor.SetInput(text)
            if actor.GetVisibility() != bool(text):
                actor.SetVisibility(bool(text))

    def detach(self) -> None:
        """Stop following the camera and take the letters off the view (once)."""
        if self._tag is not None:
            self.renderer.RemoveObserver(self._tag)
            for actor in self.actors.values():
                self.renderer.RemoveViewProp(actor)
        self._tag = None


@lru_cache(maxsize=1)
def _gl_front_face() -> Callable[[int], Any] | None:
    """OpenGL's ``glFrontFace`` (None where no OpenGL library can be loaded).

    VTK keeps no state of its own for the front face and never sets it, so
    setting it around one renderer's drawing is safe.
    """
    if sys.platform == "win32":  # pragma: no cover - Windows
        try:
            return ctypes.WinDLL("opengl32").glFrontFace  # type: ignore[attr-defined]
        except (OSError, AttributeError):
            return None
    names = [ctypes.util.find_library("OpenGL"), ctypes.util.find_library("GL")]
    for name in [*filter(None, names), "libOpenGL.so.0", "libGL.so.1"]:
        try:
            fn = ctypes.CDLL(name).glFrontFace
        except (OSError, AttributeError):
            continue
        fn.argtypes, fn.restype = [ctypes.c_uint], None
        return fn
    return None  # pragma: no cover - no OpenGL library


class DisplayMirror:
    """Reflect what one renderer shows, never the data (see the module docstring).

    ``when()`` (optional) says whether the reflection applies to what the view
    shows now; it is checked before each render.  Attributes: ``world`` —
    the 4x4 reflection of :meth:`reflect_world` or None; ``screen`` — True
    after :meth:`flip_screen`.
    """

    def __init__(self, renderer: Any, when: Callable[[], bool] | None = None) -> None:
        self.renderer = renderer
        self.when = when
        self.world: np.ndarray | None = None
        self.screen = False
        self._front_cw = False
        self._tags = [
            renderer.AddObserver("StartEvent", self._start),
            renderer.AddObserver("EndEvent", self._end),
        ]

    @property
    def active(self) -> bool:
        """The display is reflected now (an odd number of reflections applied)."""
        on = self.world is not None and (self.when is None or self.when())
        return bool(on) != self.screen

    def reflect_world(self, matrix: np.ndarray | None) -> None:
        """Show the scene reflected by the 4x4 ``matrix`` (:func:`reflection`); None: as it is.

        The camera then stands in the reflected scene: set its position after this.
        """
        self.world = None if matrix is None else np.asarray(matrix, float)
        self._apply()

    def flip_screen(self, on: bool) -> None:
        """Flip the picture left to right (True) or not (False)."""
        self.screen = bool(on)
        self._apply()

    def _apply(self) -> None:
        from vtkmodules.vtkCommonMath import vtkMatrix4x4
        from vtkmodules.vtkCommonTransforms import vtkTransform

        camera = self.renderer.GetActiveCamera()
        on = self.world is not None and (self.when is None or self.when())
        wanted = self.world if on and self.world is not None else np.eye(4)
        current = camera.GetModelTransformMatrix()
        if any(current.GetElement(i, j) != wanted[i, j] for i in range(4) for j in range(4)):
            m = vtkMatrix4x4()
            for i in range(4):
                for j in range(4):
                    m.SetElement(i, j, float(wanted[i, j]))
            camera.SetModelTransformMatrix(m)
        flipped = camera.GetUserViewTransform() is not None
        if flipped != self.screen:
            if self.screen:
                flip = vtkTransform()
                flip.Scale(-1.0, 1.0, 1.0)
                camera.SetUserViewTransform(flip)
            else:
                camera.SetUserViewTransform(None)

    def _start(self, *_args: Any) -> None:
        self._apply()
        self._front_cw = self.active
        front_face = _gl_front_face() if self._front_cw else None
        if front_face is not None:
            front_face(_GL_CW)

    def _end(self, *_args: Any) -> None:
        front_face = _gl_front_face() if self._front_cw else None
        if front_face is not None:
            front_face(_GL_CCW)
        self._front_cw = False

    def detach(self) -> None:
        for tag in self._tags:
            self.renderer.RemoveObserver(tag)
        self._tags = []


def mirror_of(renderer: Any) -> DisplayMirror:
    """The renderer's :class:`DisplayMirror` (made on first use; one per renderer)."""
    mirror = getattr(renderer, "_workbench_mirror", None)
    if mirror is None:
        mirror = DisplayMirror(renderer)
        renderer._workbench_mirror = mirror
    return mirror
