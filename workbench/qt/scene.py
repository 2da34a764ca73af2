"""The 3D scene of the window: named layers drawn in one pyvista plotter.

Units mm, everything in the specimen's **input frame** (the skull file's
coordinates), so the evidence, landmarks, dowels and the fitted face overlay.

Layers (``LAYERS``) are replaced as a whole when their data change (one
actor per layer, addressed by name), keep their visibility and opacity, and
renders are coalesced: :meth:`SceneView.request_render` schedules one render
on the next event-loop turn however many layers changed.  The scene never
writes the case; it only draws what the window hands it.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
from PySide6.QtCore import QTimer

from workbench.core.mesh import Mesh
from workbench.render.snapshots import to_polydata

#: layer name → menu title
LAYERS = {
    "skull": "Skull", "landmarks": "Landmarks", "dowels": "Dowels", "guides": "Guides",
    "face": "Face (skin)", "truth": "True skin (compare)",
}
BONE = (0.93, 0.89, 0.80)
SKIN = (0.91, 0.72, 0.60)
STATUS_COLOURS = {"placed": (0.10, 0.70, 0.25), "suggested": (1.0, 0.55, 0.0)}
SELECTED = (1.0, 0.95, 0.1)
DOWEL = (0.15, 0.35, 0.85)
GUIDE = (0.85, 0.10, 0.55)


class SceneView:
    """Named layers over a plotter (``pyvistaqt.QtInteractor`` or ``pv.Plotter``)."""

    def __init__(self, plotter: Any) -> None:
        self.plotter = plotter
        self.visible: dict[str, bool] = dict.fromkeys(LAYERS, True)
        self.opacity: dict[str, float] = {"skull": 1.0, "face": 0.6, "truth": 1.0}
        self._actors: dict[str, list[Any]] = {}
        self._render_pending = False
        self.renders = 0
        plotter.set_background("#2b2f36", top="#59606b")

    # ------------------------------------------------------------ rendering
    def request_render(self) -> None:
        """Render once on the next event-loop turn."""
        if not self._render_pending:
            self._render_pending = True
            QTimer.singleShot(0, self.render_now)

    def render_now(self) -> None:
        self._render_pending = False
        if getattr(self.plotter, "_closed", False) or self.plotter.render_window is None:
            return
        self.plotter.render()
        self.renders += 1

    # ------------------------------------------------------------ layers
    def actors(self, layer: str) -> list[Any]:
        return list(self._actors.get(layer, []))

    def has(self, layer: str) -> bool:
        return bool(self._actors.get(layer))

    def clear(self, layer: str) -> None:
        for actor in self._actors.pop(layer, []):
            self.plotter.remove_actor(actor, render=False)
        self.request_render()

    def _add(self, layer: str, actor: Any) -> None:
        self._actors.setdefault(layer, []).append(actor)
        actor.SetVisibility(self.visible.get(layer, True))

    def set_visible(self, layer: str, on: bool) -> None:
        self.visible[layer] = bool(on)
        for actor in self._actors.get(layer, []):
            actor.SetVisibility(bool(on))
        self.request_render()

    def set_opacity(self, layer: str, value: float) -> None:
        self.opacity[layer] = float(value)
        for actor in self._actors.get(layer, [])[:1]:
            actor.GetProperty().SetOpacity(float(value))
        self.request_render()

    def reset_camera(self, anterior: Sequence[float] | None = None,
                     superior: Sequence[float] | None = None) -> None:
        """Look at the face (``anterior`` toward the camera) when the orientation is known."""
        if anterior is not None and superior is not None:
            a = np.asarray(anterior, float)
            focus = np.asarray(self.plotter.center, float)
            self.plotter.camera_position = [tuple(focus + 600.0 * a), tuple(focus),
                                            tuple(np.asarray(superior, float))]
        self.plotter.reset_camera()
        self.request_render()

    # ------------------------------------------------------------ content
    def show_skull(self, mesh: Mesh | None) -> Any:
        self.clear("skull")
        if mesh is None:
            return None
        actor = self.plotter.add_mesh(to_polydata(mesh), color=BONE, smooth_shading=True,
                                      opacity=self.opacity["skull"], pickable=True,
                                      name="layer_skull", render=False)
        self._add("skull", actor)
        self.request_render()
        return actor

    def show_landmarks(self, points: np.ndarray, statuses: Sequence[str],
                       selected: np.ndarray | None = None, label: str = "") -> None:
        """Placed (green) and suggested (orange) points; the selected one in yellow."""
        self.clear("landmarks")
        radius = self._marker_size()
        for status, colour in STATUS_COLOURS.items():
            mask = np.array([s == status for s in statuses], dtype=bool)
            if mask.any():
                actor = self.plotter.add_points(
                    np.asarray(points)[mask], color=colour, point_size=radius,
                    render_points_as_spheres=True, pickable=False, render=False,
                    name=f"layer_landmarks_{status}")
                self._add("landmarks", actor)
        if selected is not None and np.isfinite(selected).all():
            actor = self.plotter.add_points(np.asarray(selected, float)[None], color=SELECTED,
                                            point_size=radius * 1.8, pickable=False,
                                            render_points_as_spheres=True, render=False,
                                            name="layer_landmarks_selected")
            self._add("landmarks", actor)
            if label:
                labels = self.plotter.add_point_labels(
                    np.asarray(selected, float)[None], [label], font_size=14, point_size=1,
                    shape_opacity=0.6, always_visible=True, pickable=False, render=False,
                    name="layer_landmarks_label")
                self._add("landmarks", labels)
        self.request_render()

    def show_dowels(self, origins: np.ndarray, tips: np.ndarray) -> None:
        """Each dowel as a line from its skull origin to its tip, with a tip sphere."""
        import pyvista as pv

        self.clear("dowels")
        if len(origins):
            n = len(origins)
            pts = np.vstack([origins, tips])
            lines = np.column_stack([np.full(n, 2), np.arange(n), np.arange(n) + n]).ravel()
            poly = pv.PolyData(pts, lines=lines)
            self._add("dowels", self.plotter.add_mesh(poly, color=DOWEL, line_width=4,
                                                      pickable=False, render=False,
                                                      name="layer_dowels_pegs"))
            self._add("dowels", self.plotter.add_points(
                np.asarray(tips), color=DOWEL, point_size=self._marker_size() * 0.8,
                render_points_as_spheres=True, pickable=False, render=False,
                name="layer_dowels_tips"))
        self.request_render()

    def show_face(self, mesh: Mesh | None, scalars: np.ndarray | None = None,
                  title: str = "") -> None:
        """The fitted skin; with ``scalars`` (per vertex, mm) as a colour map."""
        self.clear("face")
        if mesh is None:
            return
        poly = to_polydata(mesh)
        kw: dict[str, Any] = {"color": SKIN}
        if scalars is not None:
            poly.point_data[title or "mm"] = np.asarray(scalars, float)
            kw = {"scalars": title or "mm", "cmap": "viridis",
                  "scalar_bar_args": {"title": title or "mm", "vertical": True}}
        actor = self.plotter.add_mesh(poly, smooth_shading=True, opacity=self.opacity["face"],
                                      pickable=False, render=False, name="layer_face", **kw)
        self._add("face", actor)
        self.request_render()

    def show_truth(self, mesh: Mesh | None, signed_mm: np.ndarray | None = None,
                   limit_mm: float = 5.0) -> None:
        """The true skin, coloured by signed distance (NaN grey) when given."""
        self.clear("truth")
        if mesh is None:
            return
        poly = to_polydata(mesh)
        kw: dict[str, Any] = {"color": (0.7, 0.7, 0.75)}
        if signed_mm is not None:
            poly.point_data["signed mm"] = np.asarray(signed_mm, float)
            kw = {"scalars": "signed mm", "cmap": "RdBu_r", "clim": (-limit_mm, limit_mm),
                  "nan_color": (0.6, 0.6, 0.6),
                  "scalar_bar_args": {"title": "signed mm", "vertical": True}}
        actor = self.plotter.add_mesh(poly, smooth_shading=True, opacity=self.opacity["truth"],
                                      pickable=False, render=False, name="layer_truth", **kw)
        self._add("truth", actor)
        self.request_render()

    def show_guides(self, segments: list[tuple[np.ndarray, np.ndarray]],
                    points: np.ndarray) -> None:
        """Guide lines (pairs of end points) and guide points, input frame."""
        import pyvista as pv

        self.clear("guides")
        if segments:
            pts = np.array([p for seg in segments for p in seg], float)
            n = len(segments)
            lines = np.column_stack([np.full(n, 2), 2 * np.arange(n), 2 * np.arange(n) + 1]).ravel()
            self._add("guides", self.plotter.add_mesh(pv.PolyData(pts, lines=lines), color=GUIDE,
                                                      line_width=3, pickable=False, render=False,
                                                      name="layer_guides_lines"))
        if len(points):
            self._add("guides", self.plotter.add_points(
                np.asarray(points, float), color=GUIDE, point_size=self._marker_size(),
                render_points_as_spheres=True, pickable=False, render=False,
                name="layer_guides_points"))
        self.request_render()

    def _marker_size(self) -> float:
        return 12.0
