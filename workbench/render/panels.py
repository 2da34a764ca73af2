"""A row of views side by side in one off-screen picture: the layout every report picture uses.

:func:`panel_row` makes the plotter (one row of ``n`` panels, each ``size``
pixels, no borders) and :func:`each_panel` walks its panels, each made
current with a white background, so the pictures of the reconstruction,
scan-fit, age and validation reports are laid out the same way.
"""

from __future__ import annotations

from collections.abc import Iterable, Iterator
from typing import TYPE_CHECKING, TypeVar

if TYPE_CHECKING:
    import pyvista as pv

T = TypeVar("T")


def panel_row(n: int, size: tuple[int, int] | list[int]) -> pv.Plotter:
    """An off-screen plotter of ``n`` panels in one row, each ``size`` (width, height) pixels."""
    import pyvista as pv

    return pv.Plotter(
        off_screen=True,
        shape=(1, n),
        window_size=[size[0] * n, size[1]],
        border=False,
    )


def each_panel(plotter: pv.Plotter, items: Iterable[T]) -> Iterator[tuple[int, T]]:
    """``(column, item)`` for each panel of the row in turn, the panel made current and white."""
    for col, item in enumerate(items):
        plotter.subplot(0, col)
        plotter.set_background("white")  # type: ignore[arg-type]  # pyvista stub bug: wraps-typed method
        yield col, item
