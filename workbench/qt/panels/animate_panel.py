"""Animate dock: a reference head's expression presets, muscle sliders, jaw, Relax.

Widgets and signals only; :class:`workbench.qt.animate_ops.AnimateTool`
drives the :class:`workbench.services.animation.Animator` and the 3D view,
and hands the animator's state back through :meth:`AnimatePanel.show_state`.
Contractions are 0..1 (slider 0..100 %), the jaw in degrees (positive
opens).  These controls are view state: nothing here edits the case.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping

from PySide6.QtCore import Qt, Signal
from PySide6.QtWidgets import (
    QCheckBox,
    QComboBox,
    QFormLayout,
    QGridLayout,
    QGroupBox,
    QHBoxLayout,
    QLabel,
    QPushButton,
    QSlider,
    QVBoxLayout,
    QWidget,
)

#: head chooser entries: title → reference head sex
HEADS = {"Reference male": "male", "Reference female": "female"}
#: jaw slider range (degrees; the service allows more, 20° is a wide-open mouth)
JAW_MAX_DEG = 20.0
#: muscle groups of the sliders, by code stem (first match wins)
GROUPS: tuple[tuple[str, tuple[str, ...]], ...] = (
    ("Brow and forehead", ("frontalis", "corrugator")),
    ("Eyes", ("orbicularis_oculi",)),
    ("Cheeks and upper lip", ("zygomaticus", "risorius", "levator_labii")),
    ("Lips", ("orbicularis_oris",)),
    ("Lower lip, chin and jaw", ("triangularis", "quadratus", "mentalis", "mylohyoideus")),
)


def group_of(code: str) -> str:
    for title, stems in GROUPS:
        if any(code.startswith(s) for s in stems):
            return title
    return "Other"


def muscle_title(code: str) -> str:
    """``zygomaticus_major_l`` → ``zygomaticus major (L)``."""
    stem, _, side = code.rpartition("_")
    if side in ("l", "r") and stem:
        return f"{stem.replace('_', ' ')} ({side.upper()})"
    return code.replace("_", " ")


class AnimatePanel(QWidget):
    """See the module docstring.

    Signals
    -------
    head_changed(str)          "male" or "female"
    expression_changed(str, float)   preset name and intensity 0..1
    muscle_changed(str, float)       muscle code and contraction 0..1
    jaw_changed(float)         degrees
    relax_requested()
    bones_toggled(bool)        show the skull and teeth under a translucent skin
    """

    head_changed = Signal(str)
    expression_changed = Signal(str, float)
    muscle_changed = Signal(str, float)
    jaw_changed = Signal(float)
    relax_requested = Signal()
    bones_toggled = Signal(bool)

    def __init__(self, expressions: Iterable[str] = (), parent: QWidget | None = None) -> None:
        super().__init__(parent)
        self._quiet = False
        layout = QVBoxLayout(self)
        intro = QLabel(
            "Move a reference head's face: presets, single muscles, the jaw. "
            "View only: the case is not changed."
        )
        intro.setWordWrap(True)
        layout.addWidget(intro)

        form = QFormLayout()
        self.head = QComboBox()
        self.head.addItems(list(HEADS))
        self.head.currentTextChanged.connect(lambda t: self.head_changed.emit(HEADS[t]))
        form.addRow("Head", self.head)
        self.expression = QComboBox()
        self.expression.addItems(list(expressions))
        self.expression.setToolTip("FACS-based presets (EMFACS prototypes and single action units)")
        self.expression.currentTextChanged.connect(lambda _t: self._emit_expression())
        form.addRow("Expression", self.expression)
        self.intensity, self.intensity_value = _slider(100, 100)
        self.intensity.valueChanged.connect(lambda _v: self._emit_expression())
        form.addRow("Intensity", _row(self.intensity, self.intensity_value))
        self.jaw, self.jaw_value = _slider(int(JAW_MAX_DEG * 10), 0, unit="°", scale=0.1)
        self.jaw.valueChanged.connect(self._emit_jaw)
        form.addRow("Jaw opening", _row(self.jaw, self.jaw_value))
        layout.addLayout(form)

        buttons = QHBoxLayout()
        self.relax = QPushButton("Relax")
        self.relax.setToolTip("All muscles relaxed, jaw closed: the face returns to rest")
        self.relax.clicked.connect(self.relax_requested)
        buttons.addWidget(self.relax)
        self.bones = QCheckBox("Skull and teeth")
        self.bones.toggled.connect(self.bones_toggled)
        buttons.addWidget(self.bones)
        buttons.addStretch(1)
        layout.addLayout(buttons)
        self.status = QLabel("Open this dock to load the head.")
        self.status.setWordWrap(True)
        layout.addWidget(self.status)

        self._muscle_box = QWidget()
        self._muscle_layout = QVBoxLayout(self._muscle_box)
        self._muscle_layout.setContentsMargins(0, 0, 0, 0)
        layout.addWidget(self._muscle_box)
        layout.addStretch(1)
        self.muscles: dict[str, QSlider] = {}
        self._muscle_values: dict[str, QLabel] = {}

    # ------------------------------------------------------------ reading
    def sex(self) -> str:
        return HEADS[self.head.currentText()]

    def weight(self) -> float:
        return self.intensity.value() / 100.0

    def _emit_jaw(self, value: int) -> None:
        if not self._quiet:
            self.jaw_changed.emit(value / 10.0)

    def _emit_muscle(self, code: str, value: int) -> None:
        if not self._quiet:
            self.muscle_changed.emit(code, value / 100.0)

    def _emit_expression(self) -> None:
        self.expression_changed.emit(self.expression.currentText(), self.weight())

    # ------------------------------------------------------------ showing
    def set_muscles(self, codes: Iterable[str]) -> None:
        """One slider per muscle code (0..100 %), grouped by region."""
        while self._muscle_layout.count():
            item = self._muscle_layout.takeAt(0)
            widget = item.widget() if item is not None else None
            if widget is not None:
                widget.deleteLater()
        self.muscles.clear()
        self._muscle_values.clear()
        grids: dict[str, QGridLayout] = {}
        for code in codes:
            title = group_of(code)
            grid = grids.get(title)
            if grid is None:
                box = QGroupBox(title)
                grid = grids[title] = QGridLayout(box)
                grid.setColumnStretch(1, 1)
                self._muscle_layout.addWidget(box)
            slider, value = _slider(100, 0)
            slider.setToolTip(code)
            slider.valueChanged.connect(lambda v, c=code: self._emit_muscle(c, v))
            row = grid.rowCount()
            grid.addWidget(QLabel(muscle_title(code)), row, 0)
            grid.addWidget(slider, row, 1)
            grid.addWidget(value, row, 2)
            self.muscles[code] = slider
            self._muscle_values[code] = value

    def show_state(self, contraction: Mapping[str, float], jaw_deg: float) -> None:
        """Set the sliders to the animator's values without emitting signals."""
        self._quiet = True  # the value labels follow, the signals do not fire
        try:
            for code, slider in self.muscles.items():
                slider.setValue(round(100 * float(contraction.get(code, 0.0))))
            self.jaw.setValue(round(10 * min(max(jaw_deg, 0.0), JAW_MAX_DEG)))
        finally:
            self._quiet = False

    def show_status(self, text: str) -> None:
        self.status.setText(text)


def _slider(
    maximum: int, value: int, *, unit: str = " %", scale: float = 1.0
) -> tuple[QSlider, QLabel]:
    slider = QSlider(Qt.Orientation.Horizontal)
    slider.setRange(0, maximum)
    slider.setValue(value)
    label = QLabel()
    label.setMinimumWidth(44)
    label.setAlignment(Qt.AlignmentFlag.AlignRight | Qt.AlignmentFlag.AlignVCenter)

    def show(v: int) -> None:
        label.setText(f"{v * scale:.{1 if scale < 1 else 0}f}{unit}")

    slider.valueChanged.connect(show)
    show(value)
    return slider, label


def _row(*widgets: QWidget) -> QWidget:
    box = QWidget()
    row = QHBoxLayout(box)
    row.setContentsMargins(0, 0, 0, 0)
    for w in widgets:
        row.addWidget(w)
    return box
