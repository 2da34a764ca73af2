"""Lighter drawing while the user rotates the view or drags something.

On a software renderer (llvmpipe under Xvfb, remote desktops) a 100k-triangle
skull with 4× multisampling takes 130 ms a frame — too slow for a fluid drag.
While the user interacts, :class:`InteractiveDetail` draws

* the skull from a decimated copy (:data:`LIGHT_TRIANGLES` triangles, made
  once per skull in the worker thread), and
* without anti-aliasing (neither multisampling nor FXAA),

and restores the full surface and anti-aliasing (one full-quality render)
when the interaction ends.  Figures: ``benchmarks/bench_gui.py``.

The decimated copy is for drawing only: picking and every measurement use
the full surface (:mod:`workbench.qt.picking`).  Units mm, input frame.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from workbench.core import helper_process
from workbench.core.mesh import Mesh
from workbench.render.snapshots import to_polydata

#: triangles of the skull drawn during an interaction
LIGHT_TRIANGLES = 25_000
#: surfaces smaller than this are always drawn in full
MIN_TRIANGLES = 40_000

Submit = Callable[..., object]  # TaskRunner.submit (its token is not used here)


def decimated(mesh: Mesh, triangles: int = LIGHT_TRIANGLES) -> Mesh:
    """A copy of ``mesh`` with about ``triangles`` triangles (quadric decimation, mm kept).

    ``fast_simplification``, no VTK (VTK filters in a worker thread beside
    the GUI thread's rendering corrupted the heap, observed under Xvfb), run
    in the helper process because it holds the GIL throughout.  Called from
    the worker thread; the GUI thread turns the result into VTK data.
    """
    if mesh.n_faces <= triangles:
        return mesh
    # fast_simplification keeps the GIL for its whole run (~230 ms at 100k
    # triangles), which would freeze the GUI thread: run it in the helper process
    v, f = helper_process.call(
        "workbench.core.isosurface:decimate", mesh.vertices, mesh.faces, triangles
    )
    return Mesh(v, f)


def with_normals(mesh: Mesh) -> Mesh:
    """``mesh`` with its :attr:`Mesh.vertex_normals` computed (call in a worker).

    The normals are cached on the mesh, so the GUI thread's
    ``to_polydata(mesh, normals=True)`` only copies them.
    """
    _ = mesh.vertex_normals
    return mesh


class InteractiveDetail:
    """See the module docstring.

    Parameters
    ----------
    plotter
        The view (``pyvistaqt.QtInteractor``).
    submit : callable
        ``submit(channel, text, fn, on_done, on_error)`` of the window's
        :class:`~workbench.qt.workers.TaskRunner` (the decimation runs there).
    """

    def __init__(self, plotter: Any, submit: Submit) -> None:
        self.plotter = plotter
        self.submit = submit
        self.active = False
        self._actor: Any = None
        self._full: Any = None
        self._light: Any = None
        self._samples = int(plotter.render_window.GetMultiSamples())
        self._fxaa = False
        # the interactor style announces every rotation, pan and zoom
        iren = self._iren = plotter.iren.interactor
        self._tags = [
            iren.AddObserver("StartInteractionEvent", lambda *_a: self.begin()),
            iren.AddObserver("EndInteractionEvent", lambda *_a: self.end()),
        ]

    def detach(self) -> None:
        """Remove the VTK observers and forget the actors (before the view closes)."""
        for tag in self._tags:
            self._iren.RemoveObserver(tag)
        self._tags = []
        self._actor = self._full = self._light = None

    # ------------------------------------------------------------ the surface
    def set_skull(self, actor: Any, full: Any, mesh: Mesh | None = None) -> None:
        """The skull ``actor`` draws ``full`` (a ``pyvista.PolyData`` made from ``mesh``).

        The light copy is made in the worker from ``mesh`` (immutable numpy
        arrays) without VTK; only the GUI thread touches VTK objects.
        """
        self.end()
        self._actor, self._full, self._light = actor, full, None
        if actor is None or full is None or mesh is None or mesh.n_faces < MIN_TRIANGLES:
            return
        self.submit(
            "lod",
            "Preparing the interactive view …",
            lambda: with_normals(decimated(mesh)),
            lambda light, a=actor: self._ready(a, to_polydata(light, normals=True)),
            lambda _exc: None,
        )

    def _ready(self, actor: Any, light: Any) -> None:
        if actor is self._actor:
            self._light = light

    @property
    def light_ready(self) -> bool:
        return self._light is not None

    # ------------------------------------------------------------ modes
    def begin(self) -> None:
        """Switch to the light drawing (idempotent)."""
        if self.active:
            return
        self.active = True
        if self._light is not None and self._actor is not None:
            self._actor.GetMapper().SetInputData(self._light)
        self._fxaa = bool(self.plotter.renderer.GetUseFXAA())
        self.plotter.renderer.SetUseFXAA(False)
        self.plotter.render_window.SetMultiSamples(0)

    def end(self, render: bool = True) -> None:
        """Back to full quality, with one render (idempotent)."""
        if not self.active:
            return
        self.active = False
        if self._actor is not None and self._full is not None:
            self._actor.GetMapper().SetInputData(self._full)
        self.plotter.render_window.SetMultiSamples(self._samples)
        self.plotter.renderer.SetUseFXAA(self._fxaa)
        if render and self.plotter.render_window is not None:
            self.plotter.update()  # one full-quality render in the next paint
