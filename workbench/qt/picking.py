"""Click-to-place picking on the skull: a click without a drag picks, a drag rotates.

The VTK interactor style still gets every mouse event (so the view rotates
as usual); this tool only watches the left button.  A press and a release
less than :data:`CLICK_TOLERANCE_PX` apart pick the skull surface under the
cursor with a ``vtkCellPicker`` restricted to the skull actor, and hand the
picked point (mm, input frame) to the callback.  A drag never picks, so
rotating the view cannot move a landmark.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np

#: largest press→release movement (display pixels) still counted as a click
CLICK_TOLERANCE_PX = 4


class ClickPicker:
    """Turns clicks on ``target_actor()`` into ``on_pick(point)`` calls."""

    def __init__(self, plotter: Any, target_actor: Callable[[], Any],
                 on_pick: Callable[[np.ndarray], None]) -> None:
        from vtkmodules.vtkRenderingCore import vtkCellPicker

        self.plotter = plotter
        self.target_actor = target_actor
        self.on_pick = on_pick
        self.enabled = True
        self._press: tuple[int, int] | None = None
        self._picker = vtkCellPicker()
        self._picker.SetTolerance(0.0005)
        iren = plotter.iren
        iren.add_observer("LeftButtonPressEvent", self._on_press)
        iren.add_observer("LeftButtonReleaseEvent", self._on_release)

    def _event_position(self) -> tuple[int, int]:
        x, y = self.plotter.iren.interactor.GetEventPosition()
        return int(x), int(y)

    def _on_press(self, *_args: Any) -> None:
        self._press = self._event_position()

    def _on_release(self, *_args: Any) -> None:
        press, self._press = self._press, None
        if press is None or not self.enabled:
            return
        x, y = self._event_position()
        if max(abs(x - press[0]), abs(y - press[1])) > CLICK_TOLERANCE_PX:
            return  # a drag: the view was rotated, nothing is picked
        point = self.pick(x, y)
        if point is not None:
            self.on_pick(point)

    def pick(self, x: int, y: int) -> np.ndarray | None:
        """The skull point under display position ``(x, y)`` (VTK pixels), or None."""
        actor = self.target_actor()
        if actor is None:
            return None
        self._picker.InitializePickList()
        self._picker.AddPickList(actor)
        self._picker.PickFromListOn()
        if not self._picker.Pick(x, y, 0, self.plotter.renderer):
            return None
        if self._picker.GetActor() is not actor:
            return None
        return np.array(self._picker.GetPickPosition(), dtype=np.float64)

    def display_position(self, point: np.ndarray) -> tuple[float, float]:
        """World point (mm) → VTK display pixels (for tests and tooltips)."""
        ren = self.plotter.renderer
        ren.SetWorldPoint(*np.asarray(point, float), 1.0)
        ren.WorldToDisplay()
        x, y, _ = ren.GetDisplayPoint()
        return float(x), float(y)
