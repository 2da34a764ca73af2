"""Skull landmarks dock: the catalogue's skull landmarks with status and confidence.

Select a row, then click on the skull (a click, not a drag) to place it:
the window turns the pick into a :class:`~workbench.commands.landmarks.PlaceLandmark`.
"Mark absent" pushes ``SetLandmarkStatus(absent)``; "Snap" asks the window to
move the selected landmark to the feature its definition names
(:mod:`workbench.services.landmarks.snap`); "Suggest the rest" asks the window
to run the automatic transfer in a worker thread.  The panel only
issues commands and requests; it redraws itself from the case's landmarks.
Positions are mm in the specimen's input frame.
"""

from __future__ import annotations

from dataclasses import replace

from PySide6.QtCore import Qt, Signal
from PySide6.QtGui import QColor
from PySide6.QtWidgets import (
    QAbstractItemView,
    QCheckBox,
    QComboBox,
    QFormLayout,
    QHBoxLayout,
    QHeaderView,
    QLabel,
    QPushButton,
    QTableWidget,
    QTableWidgetItem,
    QVBoxLayout,
    QWidget,
)

from workbench.commands.landmarks import DeleteLandmark, ReplaceLandmarkSet, SetLandmarkStatus
from workbench.commands.reconstruction_setup import SetOrientation
from workbench.core.landmarks import LandmarkSet
from workbench.io.catalogue import LandmarkCatalogue
from workbench.model.reconstruction_setup import Orientation
from workbench.qt.document import Document

STATUS_TEXT = {
    "placed": "placed",
    "suggested": "suggested",
    "absent": "absent",
    "missing": "missing",
}
STATUS_BG = {"placed": "#d6f5dd", "suggested": "#ffe3c2", "absent": "#e4e4e4", "missing": ""}
DIRECTIONS = {
    "auto": None,
    "+x": (1, 0, 0),
    "-x": (-1, 0, 0),
    "+y": (0, 1, 0),
    "-y": (0, -1, 0),
    "+z": (0, 0, 1),
    "-z": (0, 0, -1),
}


SNAP_TIP = (
    "Move the selected landmark to the feature its definition names, near where it is, "
    "e.g. glabella to the most anterior midline point (S)"
)


class LandmarksPanel(QWidget):
    """See the module docstring.

    Signals
    -------
    selection_changed(str)
        Code of the selected landmark ('' for none).
    snap_requested(str)
        Code of the landmark to snap to its feature (the selected one).
    suggest_requested()
    """

    selection_changed = Signal(str)
    snap_requested = Signal(str)
    suggest_requested = Signal()

    def __init__(
        self, document: Document, catalogue: LandmarkCatalogue, parent: QWidget | None = None
    ) -> None:
        super().__init__(parent)
        self.document = document
        self.catalogue = catalogue
        self.codes = catalogue.codes("skull")
        self._row = {c: i for i, c in enumerate(self.codes)}
        self._refreshing = False

        self.table = QTableWidget(len(self.codes), 4)
        self.table.setHorizontalHeaderLabels(["Code", "Name", "Status", "Conf."])
        self.table.setSelectionBehavior(QAbstractItemView.SelectionBehavior.SelectRows)
        self.table.setSelectionMode(QAbstractItemView.SelectionMode.SingleSelection)
        self.table.setEditTriggers(QAbstractItemView.EditTrigger.NoEditTriggers)
        self.table.verticalHeader().setVisible(False)
        self.table.horizontalHeader().setSectionResizeMode(1, QHeaderView.ResizeMode.Stretch)
        for i, code in enumerate(self.codes):
            entry = catalogue.entry(code, "skull")
            self.table.setItem(i, 0, QTableWidgetItem(code))
            name = QTableWidgetItem(entry.display_name)
            name.setToolTip(entry.definition)
            self.table.setItem(i, 1, name)
            self.table.setItem(i, 2, QTableWidgetItem("missing"))
            self.table.setItem(i, 3, QTableWidgetItem(""))
        self.table.resizeColumnToContents(0)
        self.table.itemSelectionChanged.connect(self._on_selection)

        self.place_on_click = QCheckBox("Place the selected landmark by clicking the skull")
        self.place_on_click.setChecked(True)
        self.description = QLabel("Select a landmark to see its definition.")
        self.description.setWordWrap(True)
        self.description.setTextInteractionFlags(Qt.TextInteractionFlag.TextSelectableByMouse)

        self.absent_button = QPushButton("Mark absent")
        self.absent_button.setToolTip("The anatomy is missing or damaged here (A)")
        self.absent_button.clicked.connect(self.mark_absent)
        self.snap_button = QPushButton("Snap")
        self.snap_button.setToolTip(SNAP_TIP)
        self.snap_button.clicked.connect(self.request_snap)
        self.delete_button = QPushButton("Clear")
        self.delete_button.setToolTip("Forget this landmark (back to missing)")
        self.delete_button.clicked.connect(self.clear_selected)
        self.suggest_button = QPushButton("Suggest the rest")
        self.suggest_button.setToolTip(
            "Transfer the reference head's landmarks onto this skull; "
            "placed landmarks are kept and guide the transfer"
        )
        self.suggest_button.clicked.connect(self.suggest_requested.emit)
        self.accept_button = QPushButton("Accept suggested")
        self.accept_button.setToolTip(
            "Keep every suggested landmark where it is, as if placed by hand (one undo step); "
            "accepted landmarks stay put and guide later suggestions and fits"
        )
        self.accept_button.clicked.connect(self.accept_suggested)
        buttons = QHBoxLayout()
        for b in (
            self.absent_button,
            self.snap_button,
            self.delete_button,
            self.suggest_button,
            self.accept_button,
        ):
            buttons.addWidget(b)

        self.anterior = QComboBox()
        self.superior = QComboBox()
        for combo in (self.anterior, self.superior):
            combo.addItems(list(DIRECTIONS))
            combo.currentTextChanged.connect(self._on_orientation)
        orient = QFormLayout()
        orient.addRow("Face looks toward (file axes)", self.anterior)
        orient.addRow("Up is (file axes)", self.superior)

        self.summary = QLabel("")
        layout = QVBoxLayout(self)
        layout.addWidget(self.table, 1)
        layout.addWidget(self.place_on_click)
        layout.addLayout(buttons)
        layout.addLayout(orient)
        layout.addWidget(self.summary)
        layout.addWidget(self.description)
        document.case_replaced.connect(self.refresh)
        document.part_changed.connect(self._on_part)
        self.refresh()

    # ------------------------------------------------------------ state → widgets
    def _on_part(self, part: str) -> None:
        if part in ("landmarks", "orientation"):
            self.refresh()

    def refresh(self) -> None:
        self._refreshing = True
        try:
            lms = self.document.case.landmarks["skull"]
            counts = dict.fromkeys(STATUS_TEXT, 0)
            for code in self.codes:
                lm = lms.get(code)
                status = lm.status if lm is not None else "missing"
                counts[status] += 1
                row = self._row[code]
                self._cell(row, 2).setText(STATUS_TEXT[status])
                conf = "" if lm is None or status != "suggested" else f"{lm.confidence:.2f}"
                self._cell(row, 3).setText(conf)
                colour = STATUS_BG[status]
                for col in range(4):
                    self._cell(row, col).setBackground(
                        QColor(colour) if colour else QColor(0, 0, 0, 0)
                    )
            self.summary.setText(", ".join(f"{n} {s}" for s, n in counts.items()))
            orient = self.document.case.orientation
            self.anterior.setCurrentText(_direction_name(orient, "anterior"))
            self.superior.setCurrentText(_direction_name(orient, "superior"))
            self._show_description()
        finally:
            self._refreshing = False

    def _cell(self, row: int, col: int) -> QTableWidgetItem:
        """The item the constructor put in every cell."""
        item = self.table.item(row, col)
        if item is None:
            raise RuntimeError(f"landmark table cell ({row}, {col}) has no item")
        return item

    def _show_description(self) -> None:
        code = self.selected_code()
        self._enable_buttons(code)
        if not code:
            return
        entry = self.catalogue.entry(code, "skull")
        lm = self.document.case.landmarks["skull"].get(code)
        where = ""
        if lm is not None and lm.is_defined:
            where = " at (" + ", ".join(f"{v:.1f}" for v in lm.position) + ") mm"
        status = lm.status if lm is not None else "missing"
        note = f"<br><i>{lm.description}</i>" if lm is not None and lm.description else ""
        self.description.setText(
            f"<b>{entry.display_name}</b> ({code}) — {status}{where}<br>{entry.definition}{note}"
        )

    def _enable_buttons(self, code: str) -> None:
        """Snap only where it can work (a landmark with a position whose definition names a
        feature, or a midline one); Accept only while there are suggestions."""
        from workbench.io.snap_rules import load_snap_rules

        lms = self.document.case.landmarks["skull"]
        lm = lms.get(code) if code else None
        snappable = bool(code) and (
            code in load_snap_rules() or not self.catalogue.entry(code, "skull").is_bilateral
        )
        self.snap_button.setEnabled(snappable and lm is not None and lm.is_defined)
        self.snap_button.setToolTip(
            SNAP_TIP
            if snappable or not code
            else f"{code}'s definition names no feature to snap to"
        )
        self.accept_button.setEnabled(any(x.status == "suggested" for x in lms))

    # ------------------------------------------------------------ widgets → commands
    def selected_code(self) -> str:
        rows = self.table.selectionModel().selectedRows()
        return self.codes[rows[0].row()] if rows else ""

    def select(self, code: str) -> None:
        self.table.selectRow(self._row[code])

    def select_next_missing(self) -> None:
        """Move the selection to the next landmark without a position."""
        lms = self.document.case.landmarks["skull"]
        start = self._row.get(self.selected_code(), -1)
        order = self.codes[start + 1 :] + self.codes[: start + 1]
        for code in order:
            lm = lms.get(code)
            if lm is None or lm.status == "missing":
                self.select(code)
                return

    def _on_selection(self) -> None:
        self._show_description()
        self.selection_changed.emit(self.selected_code())

    def mark_absent(self) -> None:
        code = self.selected_code()
        if code:
            self.document.push(SetLandmarkStatus(surface="skull", code=code, status="absent"))

    def accept_suggested(self) -> None:
        """Every suggested skull landmark becomes placed where it is (one undoable step)."""
        lms = self.document.case.landmarks["skull"]
        suggested = [lm for lm in lms if lm.status == "suggested"]
        if not suggested:
            return
        accepted = LandmarkSet(
            lms.surface,
            tuple(
                replace(lm, status="placed", confidence=1.0) if lm.status == "suggested" else lm
                for lm in lms
            ),
        )
        self.document.push(
            ReplaceLandmarkSet("skull", accepted, f"Accept {len(suggested)} suggested landmarks")
        )

    def request_snap(self) -> None:
        code = self.selected_code()
        if code:
            self.snap_requested.emit(code)

    def clear_selected(self) -> None:
        code = self.selected_code()
        if code and code in self.document.case.landmarks["skull"]:
            self.document.push(DeleteLandmark(surface="skull", code=code))

    def _on_orientation(self) -> None:
        if self._refreshing:
            return
        a, s = DIRECTIONS[self.anterior.currentText()], DIRECTIONS[self.superior.currentText()]
        if a is None or s is None:
            if self.document.case.orientation is not None:
                self.document.push(SetOrientation(None))
            return
        if abs(sum(x * y for x, y in zip(a, s, strict=True))) > 0:
            return  # wait for a perpendicular pair
        new = Orientation(a, s)
        if new != self.document.case.orientation:
            self.document.push(SetOrientation(new))


def _direction_name(orient: Orientation | None, key: str) -> str:
    """The combo box entry of one direction (``"auto"`` if none or not along an axis)."""
    if orient is None:
        return "auto"
    vec = tuple(int(round(v)) for v in getattr(orient, key))
    for name, d in DIRECTIONS.items():
        if d == vec:
            return name
    return "auto"
