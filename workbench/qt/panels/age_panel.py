"""Age progression dock: source head, its age and sex, a target-age slider, the measurement table.

Widgets, signals and the table model only; :class:`workbench.qt.tools.age.tool.AgeTool`
runs the age service (:func:`workbench.services.age.change.age_head`) in the worker,
draws the heads and hands results back through ``show_*``.  Ages in years,
lengths in mm (each head in its Frankfort frame).

The table (:class:`MeasurementModel`) lists every measurement of the shown
result: name, value before and after (mm), z-score before (against the norms
at the source age) and after (at the target age), and the residual (after −
target, mm).  A z-score beyond :data:`Z_LIMIT` in either column is
highlighted; measurements without norms show "–" for z.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import TYPE_CHECKING, Any

from PySide6.QtCore import QAbstractTableModel, QModelIndex, QPersistentModelIndex, Qt, Signal
from PySide6.QtGui import QBrush, QColor, QFont
from PySide6.QtWidgets import (
    QAbstractItemView,
    QButtonGroup,
    QCheckBox,
    QComboBox,
    QDoubleSpinBox,
    QFormLayout,
    QHBoxLayout,
    QHeaderView,
    QLabel,
    QPushButton,
    QRadioButton,
    QSlider,
    QTableView,
    QVBoxLayout,
    QWidget,
)

if TYPE_CHECKING:
    from workbench.services.age.change import MeasurementRow

#: source head entries: title → key (``"fit"``: the case's reconstructed head)
SOURCES = {
    "Reference male": "reference:male",
    "Reference female": "reference:female",
    "Reconstructed head (this case)": "fit",
    "Fitted scan (Fit scan dock)": "scan",
}
#: the sources that exist only once made, with what to do first
MADE_SOURCES = {
    "fit": "Reconstruct the face first (Reconstruct dock)",
    "scan": "Fit a scan first (Fit scan dock)",
}
#: how before and after are shown
MODES = {"side": "Side by side", "overlay": "Overlay, coloured by distance"}
COLUMNS = ("Measurement", "Before", "After", "z before", "z after", "Residual")
#: z-scores beyond this (either sign) are highlighted: outside ±2 SD of the norms
Z_LIMIT = 2.0
HIGHLIGHT = QColor(255, 190, 170)
#: the reference heads are adults; their age for the norms (years)
DEFAULT_FROM_AGE = 18.0
DEFAULT_TARGET_AGE = 8


def out_of_range(z: float) -> bool:
    """True for a z-score beyond ±:data:`Z_LIMIT` (NaN, i.e. no norms, is never out of range)."""
    return math.isfinite(z) and abs(z) > Z_LIMIT


def _num(value: float, digits: int = 1) -> str:
    return f"{value:.{digits}f}" if math.isfinite(value) else "–"


class MeasurementModel(QAbstractTableModel):
    """The rows of an :class:`~workbench.services.age.change.AgeResult` for a :class:`QTableView`.

    Measurements with norms (hard constraints) come first, then those that
    follow the head scale, then the unconstrained ones (landmark missing).
    """

    ORDER = {"norms": 0, "scale": 1, "unconstrained": 2}

    def __init__(self, parent: QWidget | None = None) -> None:
        super().__init__(parent)
        self.rows: list[MeasurementRow] = []

    def set_rows(self, rows: Sequence[MeasurementRow]) -> None:
        self.beginResetModel()
        self.rows = sorted(rows, key=lambda r: self.ORDER.get(r.constraint, 3))
        self.endResetModel()

    def rowCount(self, parent: QModelIndex | QPersistentModelIndex = QModelIndex()) -> int:  # noqa: B008, N802 - Qt signature
        return 0 if parent.isValid() else len(self.rows)

    def columnCount(self, parent: QModelIndex | QPersistentModelIndex = QModelIndex()) -> int:  # noqa: B008, N802 - Qt signature
        return 0 if parent.isValid() else len(COLUMNS)

    def headerData(  # noqa: N802 - Qt name
        self, section: int, orientation: Qt.Orientation, role: int = Qt.ItemDataRole.DisplayRole
    ) -> Any:
        if role == Qt.ItemDataRole.DisplayRole and orientation == Qt.Orientation.Horizontal:
            return COLUMNS[section]
        return None

    def z_of(self, row: int, column: int) -> float:
        """The z-score shown in (row, column) (columns 3 and 4), NaN elsewhere or without norms."""
        r = self.rows[row]
        if r.constraint != "norms" or column not in (3, 4):
            return float("nan")
        return r.z_before if column == 3 else r.z_after

    def highlighted(self, row: int, column: int) -> bool:
        """The cell shows a z-score beyond ±:data:`Z_LIMIT`."""
        return out_of_range(self.z_of(row, column))

    def data(
        self, index: QModelIndex | QPersistentModelIndex, role: int = Qt.ItemDataRole.DisplayRole
    ) -> Any:
        if not index.isValid():
            return None
        r, col = self.rows[index.row()], index.column()
        if role == Qt.ItemDataRole.DisplayRole:
            if col == 0:
                return r.name
            if col == 1:
                return _num(r.before_mm)
            if col == 2:
                return _num(r.after_mm)
            if col in (3, 4):
                return _num(self.z_of(index.row(), col), 2)
            return _num(r.residual_mm, 2)
        if role == Qt.ItemDataRole.TextAlignmentRole and col > 0:
            return int(Qt.AlignmentFlag.AlignRight | Qt.AlignmentFlag.AlignVCenter)
        if role == Qt.ItemDataRole.BackgroundRole and self.highlighted(index.row(), col):
            return QBrush(HIGHLIGHT)
        if role == Qt.ItemDataRole.FontRole and self.highlighted(index.row(), col):
            font = QFont()
            font.setBold(True)
            return font
        if role == Qt.ItemDataRole.ToolTipRole:
            kind = {
                "norms": "norms at both ages: z-score kept (hard constraint)",
                "scale": "no norms at both ages: follows the head-circumference scale",
                "unconstrained": "not measured",
            }.get(r.constraint, r.constraint)
            text = f"{r.measurement_id} ({r.kind}, {r.a}–{r.b}): {kind}"
            if r.constraint == "norms":
                text += (
                    f"\nnorm before {r.mean_from:.1f} ± {r.sd_from:.1f} mm, "
                    f"after {r.mean_to:.1f} ± {r.sd_to:.1f} mm"
                )
            return text + (f"\n{r.note}" if r.note else "")
        return None


class AgePanel(QWidget):
    """See the module docstring.

    Signals
    -------
    source_changed(str)      a :data:`SOURCES` key ("reference:male", "fit" ...)
    settings_changed()       sex, source age or ethnicity changed (results so far are stale)
    target_changed(int)      the slider moved (years; emitted while dragging too)
    mode_changed(str)        "side" or "overlay"
    export_requested()
    keep_requested()         "Keep in case": record these settings as the case's age study
    """

    source_changed = Signal(str)
    settings_changed = Signal()
    target_changed = Signal(int)
    mode_changed = Signal(str)
    export_requested = Signal()
    keep_requested = Signal()

    def __init__(self, ethnicities: Sequence[str] = (), parent: QWidget | None = None) -> None:
        super().__init__(parent)
        layout = QVBoxLayout(self)
        intro = QLabel(
            "A head at another age: measurements with norms keep their z-scores, the head "
            "follows the head-circumference chart. Keep in case records these settings in "
            "the case (undoable); the heads stay view only (the case has no slot for a "
            "head): Export… writes the aged head."
        )
        intro.setWordWrap(True)
        layout.addWidget(intro)
        layout.addLayout(self._build_settings(ethnicities))
        layout.addLayout(self._build_keep())
        layout.addLayout(self._build_modes())
        self._build_results(layout)
        layout.addLayout(self._build_export())

    def _build_settings(self, ethnicities: Sequence[str]) -> QFormLayout:
        """Head, sex, age now, norms population, arc increase and the target-age slider."""
        form = QFormLayout()
        self.source = QComboBox()
        self.source.addItems(list(SOURCES))
        self.source.setToolTip("The head to age: a reference head, or this case's reconstruction")
        for key in MADE_SOURCES:
            self._set_source_enabled(key, False)
        self.source.currentTextChanged.connect(lambda t: self.source_changed.emit(SOURCES[t]))
        form.addRow("Head", self.source)
        self.sex = QComboBox()
        self.sex.addItems(["male", "female"])
        self.sex.setToolTip("Norms and head-circumference chart of this sex")
        self.sex.currentTextChanged.connect(lambda _t: self.settings_changed.emit())
        form.addRow("Sex", self.sex)
        self.from_age = QDoubleSpinBox()
        self.from_age.setRange(0.0, 100.0)
        self.from_age.setDecimals(1)
        self.from_age.setSingleStep(1.0)
        self.from_age.setSuffix(" y")
        self.from_age.setValue(DEFAULT_FROM_AGE)
        self.from_age.setKeyboardTracking(False)
        self.from_age.setToolTip("The head's age now (years); the reference heads are adults")
        self.from_age.valueChanged.connect(lambda _v: self.settings_changed.emit())
        form.addRow("Age now", self.from_age)
        self.ethnicity = QComboBox()
        self.ethnicity.addItems(list(ethnicities))
        if "European" in ethnicities:
            self.ethnicity.setCurrentText("European")
        self.ethnicity.setToolTip("Population of the facial norms (Cliniface tables)")
        self.ethnicity.currentTextChanged.connect(lambda _t: self.settings_changed.emit())
        form.addRow("Norms of", self.ethnicity)
        self.arc_increase = QDoubleSpinBox()
        self.arc_increase.setRange(0.0, 10.0)
        self.arc_increase.setDecimals(0)
        self.arc_increase.setSingleStep(1.0)
        self.arc_increase.setSuffix(" %")
        self.arc_increase.setKeyboardTracking(False)
        self.arc_increase.setToolTip(
            "Young-child option (Kähler §8.5.4): arc lengths over the face grow this much more "
            "than the head scale (0-10 %)"
        )
        self.arc_increase.valueChanged.connect(lambda _v: self.settings_changed.emit())
        form.addRow("Arc increase", self.arc_increase)
        form.addRow("Target age", self._build_target())
        return form

    def _build_target(self) -> QWidget:
        """The target-age slider (whole years) and its value."""
        self.target = QSlider(Qt.Orientation.Horizontal)
        self.target.setRange(0, 40)
        self.target.setValue(DEFAULT_TARGET_AGE)
        self.target.setTickPosition(QSlider.TickPosition.TicksBelow)
        self.target.setTickInterval(5)
        self.target.setPageStep(5)
        self.target_value = QLabel()
        self.target_value.setMinimumWidth(40)
        self.target_value.setAlignment(Qt.AlignmentFlag.AlignRight | Qt.AlignmentFlag.AlignVCenter)
        self.target.valueChanged.connect(self._on_target)
        self._on_target(self.target.value(), emit=False)
        row = QWidget()
        box = QHBoxLayout(row)
        box.setContentsMargins(0, 0, 0, 0)
        box.addWidget(self.target, 1)
        box.addWidget(self.target_value)
        return row

    def _build_keep(self) -> QHBoxLayout:
        # the settings above, kept in the case: next to them, not below the table
        keep = QHBoxLayout()
        self.keep_button = QPushButton("Keep in case")
        self.keep_button.setToolTip(
            "Record these settings (head, sex, ages, norms) as the case's age study: one "
            "step on the undo stack (Edit ▸ Undo), saved with the case and shown again when "
            "it is reopened. The heads are not stored"
        )
        self.keep_button.setEnabled(False)
        self.keep_button.clicked.connect(self.keep_requested.emit)
        self.case_note = QLabel("")
        self.case_note.setWordWrap(True)
        keep.addWidget(self.keep_button, 0, Qt.AlignmentFlag.AlignTop)
        keep.addWidget(self.case_note, 1)
        return keep

    def _build_modes(self) -> QHBoxLayout:
        """Side by side or overlay."""
        modes = QHBoxLayout()
        self.mode_group = QButtonGroup(self)
        self.mode_buttons: dict[str, QRadioButton] = {}
        for key, title in MODES.items():
            button = QRadioButton(title)
            self.mode_group.addButton(button)
            self.mode_buttons[key] = button
            button.toggled.connect(lambda on, k=key: self.mode_changed.emit(k) if on else None)
            modes.addWidget(button)
        self.mode_buttons["side"].setChecked(True)
        modes.addStretch(1)
        return modes

    def _build_results(self, layout: QVBoxLayout) -> None:
        """Status, error, figures and the measurement table of the age shown."""
        self.status = QLabel("Open this dock to load the head.")
        self.status.setWordWrap(True)
        layout.addWidget(self.status)
        self.error = QLabel("")
        self.error.setWordWrap(True)
        self.error.setStyleSheet("color: #b00020;")
        self.error.setTextInteractionFlags(Qt.TextInteractionFlag.TextSelectableByMouse)
        self.error.hide()
        layout.addWidget(self.error)
        self.figures = QLabel("")
        self.figures.setWordWrap(True)
        self.figures.setTextFormat(Qt.TextFormat.RichText)
        layout.addWidget(self.figures)

        self.model = MeasurementModel(self)
        self.table = QTableView()
        self.table.setModel(self.model)
        self.table.verticalHeader().setVisible(False)
        self.table.verticalHeader().setDefaultSectionSize(self.fontMetrics().height() + 6)
        self.table.setWordWrap(False)
        self.table.setTextElideMode(Qt.TextElideMode.ElideRight)
        self.table.setSelectionBehavior(QAbstractItemView.SelectionBehavior.SelectRows)
        self.table.setEditTriggers(QAbstractItemView.EditTrigger.NoEditTriggers)
        header = self.table.horizontalHeader()
        header.setSectionResizeMode(0, QHeaderView.ResizeMode.Stretch)
        # number columns sized once, on the first rows: re-measuring every row on each
        # slider move (ResizeToContents) cost ~40 ms of the GUI thread per move
        self._sized = False
        self.table.setMinimumHeight(240)
        layout.addWidget(
            QLabel(f"<b>Measurements</b> (mm; |z| &gt; {Z_LIMIT:g} highlighted; norms first)")
        )
        layout.addWidget(self.table, 1)

    def _build_export(self) -> QHBoxLayout:
        buttons = QHBoxLayout()
        self.export_button = QPushButton("Export…")
        self.export_button.setToolTip(
            "Write the aged head into a new folder: head/ (template pack), report.json, "
            "report.pdf and sequence.glb, as `workbench age` does"
        )
        self.export_button.clicked.connect(self.export_requested.emit)
        self.export_all = QCheckBox("every computed age")
        self.export_all.setToolTip(
            "Export each age computed so far (one pack per age and a growth sequence), "
            "not only the target age"
        )
        buttons.addWidget(self.export_button)
        buttons.addWidget(self.export_all)
        buttons.addStretch(1)
        return buttons

    # ------------------------------------------------------------ reading
    def source_key(self) -> str:
        return SOURCES[self.source.currentText()]

    def sex_value(self) -> str:
        return self.sex.currentText()

    def from_age_value(self) -> float:
        return float(self.from_age.value())

    def ethnicity_value(self) -> str | None:
        return self.ethnicity.currentText() or None

    def arc_increase_value(self) -> float:
        """The arc increase as a fraction (0-0.10)."""
        return float(self.arc_increase.value()) / 100.0

    def set_arc_increase(self, fraction: float) -> None:
        """Show ``fraction`` (0-0.10) without emitting ``settings_changed``."""
        blocked = self.arc_increase.blockSignals(True)
        try:
            self.arc_increase.setValue(100.0 * float(fraction))
        finally:
            self.arc_increase.blockSignals(blocked)

    def target_age(self) -> int:
        return int(self.target.value())

    def mode(self) -> str:
        for key, button in self.mode_buttons.items():
            if button.isChecked():
                return key
        return "side"

    def _on_target(self, value: int, emit: bool = True) -> None:
        self.target_value.setText(f"{value} y")
        if emit:
            self.target_changed.emit(int(value))

    def _set_source_enabled(self, key: str, on: bool) -> None:
        model: Any = self.source.model()
        item = model.item(list(SOURCES.values()).index(key))
        if item is not None:
            item.setEnabled(bool(on))
            item.setToolTip("" if on else MADE_SOURCES[key])

    # ------------------------------------------------------------ showing
    def set_fit_available(self, on: bool) -> None:
        """Offer (or withdraw) the case's reconstructed head as the source."""
        self.set_source_available("fit", on)

    def set_source_available(self, key: str, on: bool) -> None:
        """Offer (or withdraw) a head made in this session (``"fit"``, ``"scan"``)."""
        self._set_source_enabled(key, on)
        if not on and self.source_key() == key:
            self.source.setCurrentText("Reference male")

    def set_age_range(self, lo: float, hi: float) -> None:
        """The slider's range: whole years the norms cover."""
        self.target.setRange(int(math.ceil(lo)), int(math.floor(hi)))

    def set_keep_enabled(self, on: bool, why: str = "") -> None:
        """Enable "Keep in case" (a case is open), or disable it saying ``why``."""
        self.keep_button.setEnabled(bool(on))
        self.keep_button.setToolTip(
            self.keep_button.toolTip().split("\n\n")[0] + (f"\n\n{why}" if why and not on else "")
        )

    def show_case_note(self, text: str) -> None:
        """What the case keeps of this dock (its age study), under the buttons."""
        self.case_note.setText(text)

    def show_status(self, text: str) -> None:
        self.status.setText(text)

    def show_error(self, text: str) -> None:
        """A readable message in the dock ('' hides it)."""
        self.error.setText(text)
        self.error.setVisible(bool(text))

    def show_rows(self, rows: Sequence[MeasurementRow]) -> None:
        self.model.set_rows(rows)
        if rows and not self._sized:
            self._sized = True
            for col in range(1, len(COLUMNS)):
                self.table.resizeColumnToContents(col)

    def show_figures(self, html: str) -> None:
        self.figures.setText(html)
