"""Mouse tools of the 3D view: click to place, drag a landmark along the skull.

The VTK interactor style still gets every mouse event it should (so the
view rotates as usual); this tool watches the left button with a higher
observer priority than the style:

* **Click** — a press and a release less than :data:`CLICK_TOLERANCE_PX`
  apart pick the skull surface under the cursor and hand the point to
  ``on_pick``.  A drag that started elsewhere rotates the view and never
  picks, so rotating cannot move a landmark.
* **Drag a landmark** — a press within :data:`GRAB_RADIUS_PX` of the
  *selected* landmark (``grab_target()`` gives its code and position) grabs
  it: the press is withheld from the interactor style (the view does not
  rotate), every mouse move picks the skull under the cursor and calls
  ``on_drag(code, point)``, and the release calls ``on_drag_end(code,
  point)`` once (point None when the cursor never met the skull).  Esc is
  handled by the window (``cancel_drag``).

Picking casts the camera ray through the pixel against the skull's
full-resolution surface (``target_surface()``, a ``vtkPolyData``) with a
``vtkStaticCellLocator`` (a spatial index), so a pick on a 100k-triangle
skull costs well under a millisecond even while the view draws a lighter
level of detail.  Points are mm in the input frame.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np

#: largest press→release movement (display pixels) still counted as a click
CLICK_TOLERANCE_PX = 4
#: a press this close (display pixels) to the selected landmark grabs it
GRAB_RADIUS_PX = 10.0
#: observer priority above the interactor style's (0.0)
PRIORITY = 10.0

GrabTarget = Callable[[], "tuple[str, np.ndarray] | None"]


class ClickPicker:
    """Clicks on ``target_actor()`` → ``on_pick(point)``; landmark drags → ``on_drag*``."""

    def __init__(
        self,
        plotter: Any,
        target_actor: Callable[[], Any],
        on_pick: Callable[[np.ndarray], None],
        *,
        target_surface: Callable[[], Any] | None = None,
        grab_target: GrabTarget | None = None,
        on_drag: Callable[[str, np.ndarray], None] | None = None,
        on_drag_start: Callable[[str], None] | None = None,
        on_drag_end: Callable[[str, np.ndarray | None], None] | None = None,
    ) -> None:
        self.plotter = plotter
        self.target_actor: Callable[[], Any] | None = target_actor  # None once detached
        self.target_surface: Callable[[], Any] | None = target_surface
        self.on_pick = on_pick
        self.grab_target = grab_target
        self.on_drag = on_drag
        self.on_drag_start = on_drag_start
        self.on_drag_end = on_drag_end
        self.enabled = True
        self.dragging: str | None = None
        self._last: np.ndarray | None = None
        self._press: tuple[int, int] | None = None
        self._located: tuple[Any, Any] | None = None
        self._tags: dict[str, int] = {}
        iren = self._iren = plotter.iren.interactor
        for event, handler in (
            ("LeftButtonPressEvent", self._on_press),
            ("MouseMoveEvent", self._on_move),
            ("LeftButtonReleaseEvent", self._on_release),
        ):
            self._tags[event] = iren.AddObserver(event, handler, PRIORITY)
        # A press the style handled (a rotation, or a click) makes the style grab
        # the mouse focus: its release then reaches only the style, so the
        # click is also watched there (pyvista registers release events on
        # the style for this reason).
        self._style_observer = (
            plotter.iren.style,
            plotter.iren.style.AddObserver("LeftButtonReleaseEvent", self._on_style_release),
        )

    def detach(self) -> None:
        """Remove the VTK observers (before the view closes).

        VTK holds these Python callbacks, and through them this tool and the
        view's wrapper; left in place they are released only when VTK frees
        the interactor, after Qt may already have deleted the widget.
        """
        for tag in self._tags.values():
            self._iren.RemoveObserver(tag)
        self._tags.clear()
        style, tag = self._style_observer
        style.RemoveObserver(tag)
        self.target_actor = self.target_surface = None
        self._located = None

    # ------------------------------------------------------------ events
    def _event_position(self) -> tuple[int, int]:
        x, y = self.plotter.iren.interactor.GetEventPosition()
        return int(x), int(y)

    def _swallow(self, obj: Any, event: str) -> None:
        """Keep this event from the interactor style (no rotation while dragging)."""
        obj.GetCommand(self._tags[event]).SetAbortFlag(1)

    def _on_press(self, obj: Any, event: str) -> None:
        self._press = self._event_position()
        if not self.enabled or self.grab_target is None:
            return
        target = self.grab_target()
        if target is None:
            return
        code, position = target
        x, y = self.display_position(position)
        if np.hypot(x - self._press[0], y - self._press[1]) <= GRAB_RADIUS_PX:
            self.dragging, self._last = code, None
            self._swallow(obj, event)
            if self.on_drag_start is not None:
                self.on_drag_start(code)

    def _on_move(self, obj: Any, event: str) -> None:
        if self.dragging is None:
            return
        self._swallow(obj, event)
        point = self.pick(*self._event_position())
        if point is not None:
            self._last = point
            if self.on_drag is not None:
                self.on_drag(self.dragging, point)

    def _on_release(self, obj: Any, event: str) -> None:
        if self.dragging is not None:
            self._press = None
            self._swallow(obj, event)
            self.finish_drag()
            return
        self._click()

    def _on_style_release(self, *_args: Any) -> None:
        if self.dragging is None:
            self._click()

    def _click(self) -> None:
        press, self._press = self._press, None
        if press is None or not self.enabled:
            return
        x, y = self._event_position()
        if max(abs(x - press[0]), abs(y - press[1])) > CLICK_TOLERANCE_PX:
            return  # a drag: the view was rotated, nothing is picked
        point = self.pick(x, y)
        if point is not None:
            self.on_pick(point)

    def finish_drag(self, cancel: bool = False) -> None:
        """End a landmark drag (``cancel``: report no point, nothing moves)."""
        code, point = self.dragging, None if cancel else self._last
        self.dragging, self._last = None, None
        if code is not None and self.on_drag_end is not None:
            self.on_drag_end(code, point)

    # ------------------------------------------------------------ geometry
    def pick(self, x: int, y: int) -> np.ndarray | None:
        """The skull point under display position ``(x, y)`` (VTK pixels), or None.

        The camera ray through the pixel is intersected with the skull's
        full-resolution surface through a ``vtkStaticCellLocator`` (built
        once per surface), whatever level of detail the view is drawing.
        """
        from vtkmodules.vtkCommonCore import reference

        if self.target_actor is None:
            return None
        actor = self.target_actor()
        surface = self.target_surface() if self.target_surface is not None else None
        if actor is None or surface is None or not actor.GetVisibility():
            return None
        locator = self._locator(surface)
        near, far = self._ray(x, y)
        t, sub, cell = reference(0.0), reference(0), reference(0)
        hit, pcoords = [0.0, 0.0, 0.0], [0.0, 0.0, 0.0]
        if not locator.IntersectWithLine(near, far, 0.0, t, hit, pcoords, sub, cell):
            return None
        return np.array(hit, dtype=np.float64)

    def _ray(self, x: float, y: float) -> tuple[list[float], list[float]]:
        ren = self.plotter.renderer
        ends = []
        for depth in (0.0, 1.0):
            ren.SetDisplayPoint(float(x), float(y), depth)
            ren.DisplayToWorld()
            wx, wy, wz, w = ren.GetWorldPoint()
            ends.append([wx / w, wy / w, wz / w])
        return ends[0], ends[1]

    def _locator(self, surface: Any) -> Any:
        from vtkmodules.vtkCommonDataModel import vtkStaticCellLocator

        if self._located is None or self._located[0] is not surface:
            locator = vtkStaticCellLocator()
            locator.SetDataSet(surface)
            locator.BuildLocator()
            self._located = (surface, locator)
        return self._located[1]

    def display_position(self, point: np.ndarray) -> tuple[float, float]:
        """World point (mm) → VTK display pixels (for grabbing, tests and tooltips)."""
        ren = self.plotter.renderer
        ren.SetWorldPoint(*np.asarray(point, float), 1.0)
        ren.WorldToDisplay()
        x, y, _ = ren.GetDisplayPoint()
        return float(x), float(y)
