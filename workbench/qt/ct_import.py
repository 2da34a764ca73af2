""" "Open CT" dialog: choose the bone threshold on a live preview, then extract the surface.

A non-modal :class:`CtImportDialog` over the main window:

1. reads the volume in the window's worker (channel ``"ct-load"``) into a
   :class:`~workbench.services.ct.ct_preview.CtPreview` (block-mean preview
   volume, histogram, tissue presets);
2. shows the preview iso-surface (bone colour; the pieces the extraction
   would drop as grey debris) in its own 3D view, with an iso slider and
   spin box, "Bone preset" / "Skin preset" buttons, a histogram strip with
   the level, and live figures.  Moving the level recomputes the preview
   in the worker (channel ``"ct-preview"``); a newer preview supersedes and
   cancels an older one, so the view follows the slider;
3. "Extract surface" runs the full-resolution extraction through the
   window's :meth:`~workbench.qt.file_ops.FileTool.open_ct` (channel
   ``"open"``, with progress); on success the window holds a new case whose
   specimen is the extracted surface and the dialog closes.  "Cancel"
   during the extraction cancels the job (the window's case is unchanged)
   and returns to the preview; otherwise it closes the dialog.

Units: iso levels in the volume's units (HU for CT in Hounsfield units, the
file's raw numbers otherwise); geometry in mm in the CT's physical frame
(LPS/RAS), the frame of the extracted surface and of the new case.  Errors go
through ``window.show_error`` (never a traceback).
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from PySide6.QtCore import QEvent, QObject, QPointF, QRectF, Qt, QTimer, Signal
from PySide6.QtGui import QColor, QPainter, QPen
from PySide6.QtWidgets import (
    QDialog,
    QDoubleSpinBox,
    QFormLayout,
    QGroupBox,
    QHBoxLayout,
    QLabel,
    QProgressBar,
    QPushButton,
    QSizePolicy,
    QSlider,
    QVBoxLayout,
    QWidget,
)

from workbench.core.cancel import CancelToken
from workbench.qt.workers import show_fraction
from workbench.render.visuals.skull import add_iso_part
from workbench.render.visuals.style import set_view_background
from workbench.services.ct.ct_preview import CtPreview, PreviewSurface
from workbench.services.reconstruction import case_steps

if TYPE_CHECKING:
    from workbench.qt.hosts import CtImportHost

PRESET_COLOURS = {"bone": QColor(235, 225, 200), "skin": QColor(232, 170, 140)}
LOAD, PREVIEW, EXTRACT = "ct-load", "ct-preview", "open"
DEBOUNCE_MS = 30


class HistogramStrip(QWidget):
    """Voxel-value histogram (log counts) with the iso level and the tissue presets.

    Clicking or dragging sets the level (``iso_picked``, volume units).
    """

    iso_picked = Signal(float)

    def __init__(self, parent: QWidget | None = None) -> None:
        super().__init__(parent)
        self.setMinimumHeight(56)
        self.setSizePolicy(QSizePolicy.Policy.Expanding, QSizePolicy.Policy.Fixed)
        self.setToolTip("Voxel values (log counts); click to set the level")
        self._heights = np.zeros(0)
        self._range = (0.0, 1.0)
        self._iso: float | None = None
        self._presets: dict[str, float] = {}

    def set_data(self, counts: np.ndarray, edges: np.ndarray, presets: dict[str, float]) -> None:
        logs = np.log1p(np.asarray(counts, np.float64))
        self._heights = logs / logs.max() if logs.size and logs.max() > 0 else logs
        self._range = (float(edges[0]), float(edges[-1]))
        self._presets = dict(presets)
        self.update()

    def set_iso(self, iso: float) -> None:
        self._iso = float(iso)
        self.update()

    def _x(self, value: float) -> float:
        lo, hi = self._range
        return (value - lo) / (hi - lo or 1.0) * (self.width() - 1)

    def paintEvent(self, _event: Any) -> None:  # noqa: N802 - Qt name
        painter = QPainter(self)
        painter.fillRect(self.rect(), QColor(43, 47, 54))
        n, w, h = len(self._heights), self.width(), self.height() - 2
        if n:
            bar = w / n
            values = self._bin_values()
            for i, (height, value) in enumerate(zip(self._heights, values, strict=True)):
                above = self._iso is not None and value >= self._iso
                painter.fillRect(
                    QRectF(i * bar, h - height * (h - 4), max(bar, 1.0), height * (h - 4)),
                    QColor(225, 215, 190) if above else QColor(120, 128, 140),
                )
        for tissue, level in self._presets.items():
            colour = PRESET_COLOURS.get(tissue, QColor("white"))
            painter.setPen(QPen(colour, 1, Qt.PenStyle.DotLine))
            x = self._x(level)
            painter.drawLine(QPointF(x, 0), QPointF(x, h))
        if self._iso is not None:
            painter.setPen(QPen(QColor(255, 200, 40), 2))
            x = self._x(self._iso)
            painter.drawLine(QPointF(x, 0), QPointF(x, h))
        painter.end()

    def _bin_values(self) -> np.ndarray:
        lo, hi = self._range
        return np.linspace(lo, hi, len(self._heights) + 1)[:-1]

    def _pick(self, x: float) -> None:
        lo, hi = self._range
        self.iso_picked.emit(lo + min(max(x / max(self.width() - 1, 1), 0.0), 1.0) * (hi - lo))

    def mousePressEvent(self, event: Any) -> None:  # noqa: N802 - Qt name
        self._pick(event.position().x())

    def mouseMoveEvent(self, event: Any) -> None:  # noqa: N802 - Qt name
        if event.buttons() & Qt.MouseButton.LeftButton:
            self._pick(event.position().x())


def _units_suffix(units: str) -> str:
    return "" if units in ("", "unknown") else f" {units}"


def _fmt(value: float) -> str:
    return f"{value:,.0f}" if abs(value) >= 100 else f"{value:.3g}"


class CtImportDialog(QDialog):
    """See the module docstring.

    Parameters
    ----------
    window : CtImportHost
        The main window: ``runner``, ``open_ct``, ``show_error``; its
        ``window()`` parents the dialog, which closes with it.
    path : path
        DICOM folder or NRRD/NHDR, MetaImage, NIfTI file.
    max_voxels : int
        Size limit of the preview volume (see :mod:`workbench.services.ct.ct_preview`).

    Attributes
    ----------
    state : str
        "loading", "preview", "extracting", "done" or "closed".
    ct : CtPreview or None
        The loaded volume and its preview data.
    shown : PreviewSurface or None
        The preview surface on screen; ``previews_shown`` counts updates.
    """

    preview_updated = Signal(object)  # PreviewSurface

    def __init__(
        self, window: CtImportHost, path: str | Path, *, max_voxels: int | None = None
    ) -> None:
        super().__init__(window.window())
        from pyvistaqt import QtInteractor

        self.window_ = window
        self.runner = window.runner
        self.path = Path(path)
        self.max_voxels = max_voxels
        self.state = "loading"
        self.ct: CtPreview | None = None
        self.shown: PreviewSurface | None = None
        self.previews_shown = 0
        self.orientation: dict[str, list[float]] | None = None
        self._camera_set = False
        self._slider_steps = 1000
        self._torn_down = False
        self._extract_token: CancelToken | None = None
        self.setWindowTitle(f"Open CT — {self.path.name}")
        self.setModal(False)
        self.resize(900, 600)

        self.plotter = QtInteractor(self, auto_update=False)
        set_view_background(self.plotter)
        self.plotter.clear_events_for_key("q")  # type: ignore[arg-type]  # pyvista stub bug: wraps-typed method
        self.plotter.setMinimumSize(360, 300)

        self.title = QLabel(f"<b>{self.path.name}</b>")
        self.title.setWordWrap(True)
        self.tissue_label = QLabel("Tissue: –")
        self.tissue_label.setWordWrap(True)
        self.slider = QSlider(Qt.Orientation.Horizontal)
        self.slider.setToolTip("Iso level: voxels at or above it are inside the surface")
        self.spin = QDoubleSpinBox()
        self.spin.setKeyboardTracking(False)
        self.spin.setToolTip("Iso level in the volume's units")
        self.bone_button = QPushButton("Bone preset")
        self.skin_button = QPushButton("Skin preset")
        self.histogram = HistogramStrip()
        level_box = QGroupBox("Threshold")
        level = QVBoxLayout(level_box)
        level.addWidget(self.tissue_label)
        level.addWidget(self.slider)
        row = QHBoxLayout()
        row.addWidget(QLabel("Iso"))
        row.addWidget(self.spin, 1)
        level.addLayout(row)
        row = QHBoxLayout()
        row.addWidget(self.bone_button)
        row.addWidget(self.skin_button)
        level.addLayout(row)
        level.addWidget(self.histogram)

        self.figures: dict[str, QLabel] = {}
        figures_box = QGroupBox("Figures")
        form = QFormLayout(figures_box)
        for key, title in (
            ("iso", "Iso level"),
            ("above", "Voxels ≥ iso"),
            ("triangles", "Preview"),
            ("volume", "Volume"),
            ("spacing", "Spacing"),
            ("values", "Values"),
            ("grid", "Preview grid"),
        ):
            label = QLabel("–")
            label.setWordWrap(True)
            label.setTextInteractionFlags(Qt.TextInteractionFlag.TextSelectableByMouse)
            self.figures[key] = label
            form.addRow(title, label)

        self.status_label = QLabel(f"Reading {self.path.name} …")
        self.status_label.setWordWrap(True)
        self.progress = QProgressBar()
        self.progress.setRange(0, 0)
        self.extract_button = QPushButton("Extract surface")
        self.extract_button.setDefault(True)
        self.extract_button.setToolTip("Full-resolution surface at this level; starts a new case")
        self.cancel_button = QPushButton("Cancel")
        buttons = QHBoxLayout()
        buttons.addStretch(1)
        buttons.addWidget(self.extract_button)
        buttons.addWidget(self.cancel_button)

        side = QVBoxLayout()
        side.addWidget(self.title)
        side.addWidget(level_box)
        side.addWidget(figures_box)
        side.addStretch(1)
        side.addWidget(self.status_label)
        side.addWidget(self.progress)
        side.addLayout(buttons)
        panel = QWidget()
        panel.setLayout(side)
        panel.setFixedWidth(330)
        layout = QHBoxLayout(self)
        layout.setContentsMargins(6, 6, 6, 6)
        layout.addWidget(self.plotter, 1)
        layout.addWidget(panel)

        self._debounce = QTimer(self)
        self._debounce.setSingleShot(True)
        self._debounce.setInterval(DEBOUNCE_MS)
        self._debounce.timeout.connect(self._submit_preview)
        self.slider.valueChanged.connect(self._on_slider)
        self.spin.valueChanged.connect(self._on_spin)
        self.histogram.iso_picked.connect(self.set_iso)
        self.bone_button.clicked.connect(lambda: self.apply_preset("bone"))
        self.skin_button.clicked.connect(lambda: self.apply_preset("skin"))
        self.extract_button.clicked.connect(self.extract)
        self.cancel_button.clicked.connect(self.cancel)
        self.runner.progress_changed.connect(self._on_progress)
        self.runner.busy_changed.connect(self._check_extraction)
        window.window().installEventFilter(self)
        self._set_controls(False)
        self._load()

    # ------------------------------------------------------------ loading
    def _load(self) -> None:
        path, max_voxels = self.path, self.max_voxels

        def work(progress: Any) -> tuple[CtPreview, Any]:
            ct = (
                CtPreview.load(path, progress=progress)
                if max_voxels is None
                else CtPreview.load(path, progress=progress, max_voxels=max_voxels)
            )
            return ct, case_steps.sample_orientation(path)

        self.runner.submit(
            LOAD,
            f"Reading the CT {path.name} …",
            work,
            self._loaded,
            self._load_failed,
            progress=True,
        )

    def _loaded(self, loaded: tuple[CtPreview, Any]) -> None:
        if self.state == "closed":
            return
        self.ct, self.orientation = loaded
        ct = self.ct
        lo, hi = ct.value_range
        units = _units_suffix(ct.units)
        info = ct.describe()
        integer = ct.integer_values
        self._slider_steps = int(hi - lo) if integer and 0 < hi - lo <= 100_000 else 2000
        for widget in (self.slider, self.spin):
            widget.blockSignals(True)
        self.slider.setRange(0, max(self._slider_steps, 1))
        self.spin.setDecimals(0 if integer else 2)
        self.spin.setRange(lo, hi)
        self.spin.setSingleStep(10.0 if integer and hi - lo > 200 else (hi - lo) / 200 or 1.0)
        self.spin.setSuffix(units)
        for widget in (self.slider, self.spin):
            widget.blockSignals(False)
        counts, edges = ct.histogram(160)
        self.histogram.set_data(counts, edges, {t: c.iso for t, c in ct.presets.items()})
        ni, nj, nk = info["shape_ijk"]
        ei, ej, ek = info["extent_mm"]
        si, sj, sk = info["spacing_mm"]
        self.figures["volume"].setText(
            f"{ni} × {nj} × {nk} voxels\n{ei:.0f} × {ej:.0f} × {ek:.0f} mm ({info['frame']})"
        )
        self.figures["spacing"].setText(f"{si:.3g} × {sj:.3g} × {sk:.3g} mm")
        kind = "HU" if ct.units == "HU" else "raw values, not HU"
        self.figures["values"].setText(f"{_fmt(lo)} … {_fmt(hi)} ({kind})")
        strides = info["strides"]
        if strides == (1, 1, 1):
            self.figures["grid"].setText("full resolution")
        else:
            pi, pj, pk = info["preview_shape_ijk"]
            self.figures["grid"].setText(
                f"{pi} × {pj} × {pk} (block means of "
                f"{strides[0]} × {strides[1]} × {strides[2]} voxels)"
            )
        for tissue, button in (("bone", self.bone_button), ("skin", self.skin_button)):
            button.setToolTip(ct.presets[tissue].rule)
        self.state = "preview"
        self.progress.hide()
        self._set_controls(True)
        self.status_label.setText(
            "Move the level; the preview follows. Grey pieces are dropped by the extraction."
        )
        self.apply_preset("bone")

    def _load_failed(self, exc: BaseException) -> None:
        if self.state == "closed":
            return
        self.window_.show_error(f"Could not read the CT {self.path.name}", exc)
        self.close()

    # ------------------------------------------------------------ the level
    @property
    def iso(self) -> float:
        """The chosen level, in the volume's units."""
        return float(self.spin.value())

    def set_iso(self, iso: float) -> None:
        """Set the level (volume units); the preview follows."""
        self.spin.setValue(float(iso))  # valueChanged → slider, figures, preview

    def apply_preset(self, tissue: str) -> None:
        if self.ct is not None:
            level = self.ct.presets[tissue].iso
            if abs(level - self.iso) < 1e-9:
                self._level_changed()  # no valueChanged for the same value
            self.set_iso(level)

    def _value_of(self, position: int) -> float:
        lo, hi = self.ct.value_range if self.ct else (0.0, 1.0)
        return lo + (hi - lo) * position / max(self._slider_steps, 1)

    def _position_of(self, value: float) -> int:
        lo, hi = self.ct.value_range if self.ct else (0.0, 1.0)
        return round((value - lo) / (hi - lo or 1.0) * self._slider_steps)

    def _on_slider(self, position: int) -> None:
        self.spin.blockSignals(True)
        self.spin.setValue(self._value_of(position))
        self.spin.blockSignals(False)
        self._level_changed()

    def _on_spin(self, value: float) -> None:
        self.slider.blockSignals(True)
        self.slider.setValue(self._position_of(value))
        self.slider.blockSignals(False)
        self._level_changed()

    def _tissue(self) -> tuple[str, bool]:
        """``(nearest tissue, level is exactly its preset)``."""
        assert self.ct is not None
        tissue = self.ct.nearest_tissue(self.iso)
        return tissue, abs(self.ct.presets[tissue].iso - self.iso) < 1e-6

    def _level_changed(self) -> None:
        if self.ct is None:
            return
        iso, units = self.iso, _units_suffix(self.ct.units)
        tissue, exact = self._tissue()
        preset = self.ct.presets[tissue]
        self.tissue_label.setText(
            f"Tissue: <b>{tissue}</b> — "
            + ("preset level" if exact else f"custom level (preset {preset.iso:g}{units})")
        )
        self.tissue_label.setToolTip(preset.rule)
        self.histogram.set_iso(iso)
        summary = self.ct.summary(iso)
        self.figures["iso"].setText(f"{iso:g}{units}")
        self.figures["above"].setText(
            f"{summary.voxels_above:,} ({100 * summary.fraction_above:.2f} %, "
            f"{summary.volume_above_ml:,.0f} ml); percentile {summary.percentile:.1f}"
        )
        self._debounce.start()

    # ------------------------------------------------------------ preview
    def _submit_preview(self) -> None:
        if self.ct is None or self.state != "preview":
            return
        ct, iso, token = self.ct, self.iso, CancelToken()
        self.runner.submit(
            PREVIEW,
            f"Preview at iso {iso:g} …",
            lambda: ct.surface(iso, cancel=token),
            self._show_preview,
            self._preview_failed,
            token=token,
        )

    def _show_preview(self, surface: PreviewSurface) -> None:
        if self.state == "closed":
            return
        plotter = self.plotter
        for name, mesh in (("ct_preview", surface.mesh), ("ct_debris", surface.debris)):
            if mesh.n_faces:
                add_iso_part(plotter, name, mesh)  # bone colour; the debris grey, translucent
            else:
                plotter.remove_actor(name, render=False)  # type: ignore[arg-type]  # pyvista stub bug: wraps-typed method
        if surface.empty:
            self.figures["triangles"].setText(f"no surface ({surface.note})")
        else:
            self.figures["triangles"].setText(
                f"{surface.mesh.n_faces:,} triangles, {surface.n_components} piece"
                f"{'s' if surface.n_components != 1 else ''} "
                f"({surface.debris.n_faces:,} triangles of debris); "
                f"{1000 * surface.seconds:.0f} ms"
            )
            if not self._camera_set:
                self._reset_camera(surface)
        self.shown = surface
        self.previews_shown += 1
        plotter.update()  # one repaint (plotter.render() would render twice: signal + paint)
        self.preview_updated.emit(surface)

    def _reset_camera(self, surface: PreviewSurface) -> None:
        """Three-quarter view of the face (known sample orientation, else the CT frame's)."""
        assert self.ct is not None
        frame = self.ct.volume.frame
        known = self.orientation or {}
        anterior = np.asarray(known.get("anterior", (0.0, -1.0 if frame == "LPS" else 1.0, 0.0)))
        superior = np.asarray(known.get("superior", (0.0, 0.0, 1.0)))
        lateral = np.cross(superior, anterior)
        view = anterior * np.cos(np.radians(35)) + lateral * np.sin(np.radians(35))
        bounds = surface.mesh.bounds
        focus = bounds.mean(axis=0)
        distance = 3.0 * float(np.linalg.norm(bounds[1] - bounds[0]))
        self.plotter.camera_position = [
            tuple(focus + distance * view),
            tuple(focus),
            tuple(superior),
        ]
        self.plotter.reset_camera()  # type: ignore[call-arg]  # pyvista stub bug: wraps-typed method
        self.plotter.camera.zoom(1.3)
        self._camera_set = True

    def _preview_failed(self, exc: BaseException) -> None:
        if self.state != "closed":
            self.window_.show_error(f"Could not preview the CT {self.path.name}", exc)

    # ------------------------------------------------------------ extraction
    def extract(self) -> None:
        """Full-resolution extraction at the chosen level through the window (new case)."""
        if self.ct is None or self.state != "preview":
            return
        self._debounce.stop()
        self.runner.cancel(PREVIEW)
        tissue, exact = self._tissue()
        iso = None if exact else self.iso
        self.state = "extracting"
        self._set_controls(False)
        self.cancel_button.setEnabled(True)
        self.progress.setRange(0, 0)
        self.progress.show()
        self.status_label.setText(
            f"Extracting the {tissue} surface at {self.iso:g}{_units_suffix(self.ct.units)} …"
        )
        started = self.window_.open_ct(
            self.path, tissue, iso, volume=self.ct.volume, finished=self._extract_finished
        )
        if not started:  # the user kept the open case
            self._back_to_preview("The open case was kept.")
            return
        self._extract_token = self.runner.token(EXTRACT)

    def _extracting_here(self) -> bool:
        """True while the window's "open" job is still this dialog's extraction."""
        token = self._extract_token
        return token is not None and self.runner.token(EXTRACT) is token

    def _check_extraction(self, _busy: bool = False, _text: str = "") -> None:
        """Back to the preview if another "open" job of the window superseded the extraction."""
        token = self._extract_token
        if self.state == "extracting" and token is not None and token.cancelled:
            self._back_to_preview(
                "Another file is being opened in the window; the extraction stopped."
            )

    def _extract_finished(self, ok: bool) -> None:
        if self.state != "extracting":
            return
        if ok:
            self.state = "done"
            self.accept()
        else:
            self._back_to_preview("The extraction failed; the case is unchanged.")

    def _back_to_preview(self, text: str) -> None:
        self.state = "preview"
        self._extract_token = None
        self.progress.hide()
        self._set_controls(True)
        self.status_label.setText(text)

    def cancel(self) -> None:
        """Cancel the extraction (back to the preview), or close the dialog."""
        if self.state == "extracting":
            mine = self._extracting_here()
            self._back_to_preview("Extraction cancelled; the case is unchanged.")
            if mine:
                self.runner.cancel(EXTRACT)
            return
        self.reject()

    def _on_progress(self, channel: str, step: str, fraction: float) -> None:
        if (channel == EXTRACT and self.state == "extracting") or (
            channel == LOAD and self.state == "loading"
        ):
            show_fraction(self.progress, fraction, step)
            self.progress.setFormat(f"{step} %p%")

    def _set_controls(self, enabled: bool) -> None:
        for widget in (
            self.slider,
            self.spin,
            self.bone_button,
            self.skin_button,
            self.histogram,
            self.extract_button,
        ):
            widget.setEnabled(enabled)

    # ------------------------------------------------------------ closing
    def done(self, result: int) -> None:
        self.teardown()
        super().done(result)

    def closeEvent(self, event: Any) -> None:  # noqa: N802 - Qt name
        self.teardown()
        super().closeEvent(event)

    def eventFilter(self, watched: QObject, event: QEvent) -> bool:  # noqa: N802 - Qt name
        if watched is self.window_.window() and event.type() == QEvent.Type.Close:
            self.close()  # the window is closing: release the 3D view first
        return False

    def teardown(self) -> None:
        """Cancel this dialog's jobs (an unfinished extraction too) and close the 3D view."""
        if self._torn_down:
            return
        self._torn_down = True
        mine = self.state == "extracting" and self._extracting_here()
        self.state = "closed" if self.state != "done" else "done"
        if mine:
            self.runner.cancel(EXTRACT)
        self._debounce.stop()
        self.runner.cancel(LOAD)
        self.runner.cancel(PREVIEW)
        for signal, slot in (
            (self.runner.progress_changed, self._on_progress),
            (self.runner.busy_changed, self._check_extraction),
        ):
            try:
                signal.disconnect(slot)
            except (RuntimeError, TypeError):
                pass
        self.window_.window().removeEventFilter(self)
        self.plotter.close()  # finalize VTK while the GL context exists (HEADLESS.md)
        self.ct = None  # release the volume
