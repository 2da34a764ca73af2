"""Layers dock: one row per scene layer with a visibility box and an opacity slider.

The panel holds no state of its own.  Its widgets write to the
:class:`~workbench.qt.scene.SceneView` (``set_visible``, ``set_opacity``) and
follow the scene back through ``SceneView.layer_changed``, with their own
signals blocked while they are updated.  So the View-menu toggles, this panel
and the reconstruct panel's skin slider always show the same state, and a
change never echoes back and forth.  Opacity is shown in percent (0–100).
"""

from __future__ import annotations

from PySide6.QtCore import QSize, Qt
from PySide6.QtWidgets import QCheckBox, QGridLayout, QLabel, QSlider, QVBoxLayout, QWidget

from workbench.qt.scene import LAYERS, SceneView


class LayersPanel(QWidget):
    """See the module docstring.

    Attributes
    ----------
    checks : dict
        ``{layer: QCheckBox}`` (visibility).
    sliders : dict
        ``{layer: QSlider}`` (opacity in percent, 0–100).
    """

    def __init__(self, scene: SceneView, parent: QWidget | None = None) -> None:
        super().__init__(parent)
        self.scene = scene
        self.checks: dict[str, QCheckBox] = {}
        self.sliders: dict[str, QSlider] = {}
        self._percent: dict[str, QLabel] = {}

        grid = QGridLayout()
        grid.setHorizontalSpacing(8)
        grid.setVerticalSpacing(4)
        grid.addWidget(QLabel("<b>Layer</b>"), 0, 0)
        grid.addWidget(QLabel("<b>Opacity</b>"), 0, 1, 1, 2)
        for row, (layer, title) in enumerate(LAYERS.items(), start=1):
            check = QCheckBox(title)
            check.setObjectName(f"layer_visible_{layer}")
            check.setToolTip(f"Show or hide the {title.lower()} layer")
            check.toggled.connect(lambda on, name=layer: self.scene.set_visible(name, on))
            slider = QSlider(Qt.Orientation.Horizontal)
            slider.setObjectName(f"layer_opacity_{layer}")
            slider.setRange(0, 100)
            slider.setSingleStep(5)
            slider.setPageStep(10)
            slider.setMinimumWidth(80)
            slider.setToolTip(f"Opacity of the {title.lower()} layer (%)")
            slider.valueChanged.connect(
                lambda v, name=layer: self.scene.set_opacity(name, v / 100.0)
            )
            percent = QLabel()
            percent.setMinimumWidth(36)
            percent.setAlignment(Qt.AlignmentFlag.AlignRight | Qt.AlignmentFlag.AlignVCenter)
            grid.addWidget(check, row, 0)
            grid.addWidget(slider, row, 1)
            grid.addWidget(percent, row, 2)
            self.checks[layer], self.sliders[layer], self._percent[layer] = check, slider, percent
            self.sync(layer)
        grid.setColumnStretch(1, 1)

        layout = QVBoxLayout(self)
        layout.addLayout(grid)
        layout.addStretch(1)
        scene.layer_changed.connect(self.sync)

    def sizeHint(self) -> QSize:  # noqa: N802 - Qt name
        """Narrow by default, so the dock leaves the 3D view its room."""
        return QSize(240, super().sizeHint().height())

    def sync(self, layer: str) -> None:
        """Show the scene's state of ``layer`` without sending it back to the scene."""
        if layer not in self.checks:
            return
        visible, opacity = self.scene.visible[layer], self.scene.opacity[layer]
        percent = round(opacity * 100)
        for widget, update in (
            (self.checks[layer], lambda w: w.setChecked(visible)),
            (self.sliders[layer], lambda w: w.setValue(percent)),
        ):
            blocked = widget.blockSignals(True)
            try:
                update(widget)
            finally:
                widget.blockSignals(blocked)
        self._percent[layer].setText(f"{percent} %")
