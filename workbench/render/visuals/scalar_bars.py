"""Colour bars (keys of surfaces coloured by a value): one look for every view.

Vertical, inside the view's right edge (titles included), and added without
pyvista's immediate render (the next paint draws them; that render cost ~85 ms of
the GUI thread on top of the paint).  A bar is addressed by its title, which is also
the name of the point array it colours by.
"""

from __future__ import annotations

from typing import Any

SCALAR_BAR: dict[str, Any] = {
    "vertical": True,
    "render": False,
    "position_x": 0.82,
    "position_y": 0.25,
    "width": 0.07,
    "height": 0.5,
    "title_font_size": 14,
    "label_font_size": 12,
}


def bar_args(title: str, **extra: Any) -> dict[str, Any]:
    """``scalar_bar_args`` of ``add_mesh``: :data:`SCALAR_BAR` titled ``title`` (the readable
    name of the values and their unit, e.g. ``"signed mm"``), with ``extra`` settings
    (``n_labels``, ``fmt``) on top."""
    return dict(SCALAR_BAR, title=title, **extra)


def set_bar_visible(plotter: Any, title: str, on: bool) -> None:
    """Show or hide the colour bar titled ``title`` if the plotter has one."""
    bars = plotter.scalar_bars
    if title in bars:
        bars[title].SetVisibility(on)
