"""Fit scan dock: open a face scan, fit the reference head, show its figures, assist landmarks.

Widgets and signals only; :class:`workbench.qt.tools.scan_fit.tool.ScanFitTool`
does the work (worker jobs, drawing, picking) and hands results back through
``show_*``.  The landmark table lists the reference head's skin landmark
codes with their state (placed by the user, the fit's first guess, a guess
over a hole, or nothing) and the guess's distance to the scan (mm, its
confidence).  Units mm.
"""

from __future__ import annotations

from collections.abc import Mapping
from html import escape
from typing import TYPE_CHECKING

import numpy as np
from PySide6.QtCore import Qt, Signal
from PySide6.QtWidgets import (
    QAbstractItemView,
    QCheckBox,
    QComboBox,
    QFormLayout,
    QGridLayout,
    QHBoxLayout,
    QHeaderView,
    QLabel,
    QPushButton,
    QSlider,
    QTableWidget,
    QTableWidgetItem,
    QVBoxLayout,
    QWidget,
)

from workbench.core.landmarks import LandmarkSet
from workbench.io.tables import list_tables
from workbench.qt.panels.build_choice import build_combo

if TYPE_CHECKING:
    from workbench.commands.stack import CommandStack
    from workbench.qt.tools.scan_fit.state import FitView, OpenedScan

COLUMNS = ("Code", "Name", "State", "Conf. (mm)")
UNITS = ("auto", "mm", "cm", "m", "in")
#: drawn layers of the tool and their check-box titles
LAYER_TITLES = {"scan": "Scan", "skin": "Fitted skin", "landmarks": "Landmarks"}
STATE_TEXT = {"placed": "placed", "guess": "first guess", "over hole": "guess, over a hole"}
#: how the scan is coloured: the choices of the "Scan colours" box (key, title)
SCAN_COLOUR_CHOICES = (("distance", "distance to the fit"), ("own", "the scan's own colours"))
#: the choice for a scan that carries colours until the user picks another: the person
#: is recognised, and lid, lip and brow landmarks placed, on the scan's own colours; the
#: distance map (and the fit's figures) check the fit, one choice away
DEFAULT_SCAN_COLOURS = "own"
COLOURS_TIP = (
    "Draw the scan in its own colours (to recognise the person and place landmarks on "
    "the lid, lip and brow borders) or by its distance to the fitted skin (0–2.5 mm, to "
    "check the fit)"
)
NO_COLOURS_TIP = (
    "This scan carries no colours (PLY or OBJ vertex colours, or an OBJ texture named "
    "by its material's map_Kd): it is drawn by its distance to the fit"
)


class ScanFitPanel(QWidget):
    """See the module docstring.

    Signals
    -------
    open_requested(), fit_requested(), cancel_requested(), save_requested()
    accept_requested(), accept_all_requested(), remove_requested()
    undo_requested(), redo_requested()
    place_toggled(bool)
        Clicks on the scan place the selected code (and drags move it).
    selection_changed(str)
        The selected landmark code ('' for none).
    visibility_changed(str, bool)
        ``("scan" | "skin" | "landmarks", visible)``.
    opacity_changed(float)
        The fitted skin's opacity, 0..1.
    detail_toggled(bool)
        Draw the fitted skin with the scan's fine detail (the subdivided,
        displaced skin) instead of the animatable skin itself.
    scan_colours_changed(str)
        ``"own"``: draw the scan in its own colours; ``"distance"``: by its
        distance to the fitted skin (:data:`SCAN_COLOUR_CHOICES`).
    """

    open_requested = Signal()
    fit_requested = Signal()
    cancel_requested = Signal()
    save_requested = Signal()
    accept_requested = Signal()
    accept_all_requested = Signal()
    remove_requested = Signal()
    undo_requested = Signal()
    redo_requested = Signal()
    place_toggled = Signal(bool)
    selection_changed = Signal(str)
    visibility_changed = Signal(str, bool)
    opacity_changed = Signal(float)
    detail_toggled = Signal(bool)
    scan_colours_changed = Signal(str)

    def __init__(self, parent: QWidget | None = None) -> None:
        super().__init__(parent)
        self.codes: list[str] = []
        self._filling = False
        #: the scan colouring the user chose last (kept for the next coloured scan)
        self.preferred_scan_colours = DEFAULT_SCAN_COLOURS
        self._setting_colours = False

        self.open_button = QPushButton("Open scan…")
        self.open_button.setToolTip("A face scan: PLY, STL, OBJ, VTK or VTP (holes are fine)")
        self.open_button.clicked.connect(self.open_requested.emit)
        self.file_label = QLabel("No scan open.")
        self.file_label.setWordWrap(True)
        self.units_combo = QComboBox()
        self.units_combo.addItems(list(UNITS))
        self.units_combo.setToolTip("Units of the scan file (auto: judged from its size)")
        self.sex_combo = QComboBox()
        self.sex_combo.addItems(["male", "female"])
        self.sex_combo.setToolTip("Reference head and depth-table group")
        self.table_combo = QComboBox()
        self.table_combo.addItems(list_tables())
        self.table_combo.setToolTip("Tissue depths that place the skull under the fitted skin")
        self.build_combo = build_combo()
        self.fit_button = QPushButton("Fit")
        self.fit_button.setToolTip(
            "Fit the reference head to the scan: from zero landmarks, or seeded by the "
            "3+ placed ones"
        )
        self.fit_button.clicked.connect(self.fit_requested.emit)
        self.cancel_button = QPushButton("Cancel")
        self.cancel_button.clicked.connect(self.cancel_requested.emit)
        self.cancel_button.setEnabled(False)
        self.save_button = QPushButton("Save pack…")
        self.save_button.setToolTip(
            "Fit with the same inputs and write the template pack + fit_report.json into a "
            "new folder (an existing one is replaced only if you confirm)"
        )
        self.save_button.clicked.connect(self.save_requested.emit)
        self.state_label = QLabel("")
        self.state_label.setWordWrap(True)

        form = QFormLayout()
        top = QHBoxLayout()
        top.addWidget(self.open_button)
        top.addWidget(QLabel("units"))
        top.addWidget(self.units_combo)
        form.addRow(top)
        form.addRow(self.file_label)
        person = QHBoxLayout()
        person.addWidget(self.sex_combo, 1)
        person.addWidget(QLabel("build"))
        person.addWidget(self.build_combo, 1)
        form.addRow("Sex", person)
        form.addRow("Depth table", self.table_combo)
        buttons = QHBoxLayout()
        buttons.addWidget(self.fit_button, 2)
        buttons.addWidget(self.cancel_button, 1)
        buttons.addWidget(self.save_button, 2)
        form.addRow(buttons)
        form.addRow(self.state_label)

        self.figures = QLabel("Not fitted yet.")
        self.figures.setWordWrap(True)
        self.figures.setTextFormat(Qt.TextFormat.RichText)
        self.figures.setTextInteractionFlags(Qt.TextInteractionFlag.TextSelectableByMouse)

        shown = self._layer_controls()

        self.place_check = QCheckBox("Place and drag landmarks on the scan")
        self.place_check.setToolTip(
            "Click the scan to place the selected code; drag the selected landmark to move it"
        )
        self.place_check.toggled.connect(self.place_toggled.emit)
        self.table = QTableWidget(0, len(COLUMNS))
        self.table.setHorizontalHeaderLabels(list(COLUMNS))
        self.table.verticalHeader().setVisible(False)
        self.table.setSelectionBehavior(QAbstractItemView.SelectionBehavior.SelectRows)
        self.table.setSelectionMode(QAbstractItemView.SelectionMode.SingleSelection)
        self.table.setEditTriggers(QAbstractItemView.EditTrigger.NoEditTriggers)
        self.table.horizontalHeader().setSectionResizeMode(1, QHeaderView.ResizeMode.Stretch)
        self.table.setMinimumHeight(180)
        self.table.itemSelectionChanged.connect(self._on_selection)
        self.accept_button = QPushButton("Accept")
        self.accept_button.setToolTip("Take the selected first-guess landmark as placed")
        self.accept_button.clicked.connect(self.accept_requested.emit)
        self.accept_all_button = QPushButton("Accept all")
        self.accept_all_button.setToolTip("Take every first-guess landmark over the scan as placed")
        self.accept_all_button.clicked.connect(self.accept_all_requested.emit)
        self.remove_button = QPushButton("Remove")
        self.remove_button.setToolTip("Remove the selected placed landmark")
        self.remove_button.clicked.connect(self.remove_requested.emit)
        self.undo_button = QPushButton("Undo")
        self.undo_button.clicked.connect(self.undo_requested.emit)
        self.redo_button = QPushButton("Redo")
        self.redo_button.clicked.connect(self.redo_requested.emit)
        self.undo_button.setEnabled(False)
        self.redo_button.setEnabled(False)
        lm_buttons = QGridLayout()
        lm_buttons.addWidget(self.accept_button, 0, 0)
        lm_buttons.addWidget(self.accept_all_button, 0, 1)
        lm_buttons.addWidget(self.remove_button, 0, 2)
        lm_buttons.addWidget(self.undo_button, 1, 0)
        lm_buttons.addWidget(self.redo_button, 1, 1)
        self.legend = QLabel(
            "<span style='color:#1abf40'>●</span> placed &nbsp; "
            "<span style='color:#ff8c00'>●</span> first guess &nbsp; "
            "<span style='color:#9e6bf2'>●</span> guess over a hole &nbsp; "
            "<span style='color:#e6d600'>●</span> selected"
        )
        self.legend.setTextFormat(Qt.TextFormat.RichText)
        self.seed_label = QLabel("")
        self.seed_label.setWordWrap(True)

        layout = QVBoxLayout(self)
        layout.addLayout(form)
        layout.addWidget(self.figures)
        layout.addLayout(shown)
        layout.addWidget(QLabel("<b>Skin landmarks</b> (scan frame, mm)"))
        layout.addWidget(self.place_check)
        layout.addWidget(self.legend)
        layout.addWidget(self.table, 1)
        layout.addLayout(lm_buttons)
        layout.addWidget(self.seed_label)
        self.set_running(False)
        self.show_scan(None)

    def _layer_controls(self) -> QGridLayout:
        """The drawn layers' check boxes, the scan's colouring, the fitted skin's opacity
        and its fine detail."""
        self.layer_checks: dict[str, QCheckBox] = {}
        shown = QGridLayout()
        for col, (layer, title) in enumerate(LAYER_TITLES.items()):
            check = QCheckBox(title)
            check.setChecked(True)
            check.toggled.connect(lambda on, name=layer: self.visibility_changed.emit(name, on))
            shown.addWidget(check, 0, col)
            self.layer_checks[layer] = check
        self.opacity = QSlider(Qt.Orientation.Horizontal)
        self.opacity.setRange(0, 100)
        self.opacity.setValue(35)
        self.opacity.setToolTip("Opacity of the fitted skin over the scan (%)")
        self.opacity.valueChanged.connect(lambda v: self.opacity_changed.emit(v / 100.0))
        self.scan_colours_combo = QComboBox()
        for key, title in SCAN_COLOUR_CHOICES:
            self.scan_colours_combo.addItem(title, key)
        self.scan_colours_combo.currentIndexChanged.connect(self._on_scan_colours)
        shown.addWidget(QLabel("Scan colours"), 1, 0)
        shown.addWidget(self.scan_colours_combo, 1, 1, 1, 2)
        shown.addWidget(QLabel("Fitted skin opacity"), 2, 0)
        shown.addWidget(self.opacity, 2, 1, 1, 2)
        self.detail_check = QCheckBox("Fine detail")
        self.detail_check.setToolTip(
            "Show the fitted skin with the scan's fine detail (lid creases, lip borders, "
            "nostrils) carried onto the subdivided skin; the animatable skin is unchanged"
        )
        self.detail_check.toggled.connect(self.detail_toggled.emit)
        shown.addWidget(self.detail_check, 3, 0, 1, 3)
        return shown

    # ------------------------------------------------------------ reads
    def selected_code(self) -> str:
        rows = self.table.selectionModel().selectedRows()
        if not rows:
            return ""
        item = self.table.item(rows[0].row(), 0)
        return item.text() if item is not None else ""

    def select_code(self, code: str) -> None:
        if code in self.codes:
            self.table.selectRow(self.codes.index(code))

    def select_next_unplaced(self, after: str, placed: LandmarkSet) -> None:
        """Select the next code after ``after`` that has no placed landmark (wrapping)."""
        if after not in self.codes:
            return
        start = self.codes.index(after)
        for k in range(1, len(self.codes) + 1):
            code = self.codes[(start + k) % len(self.codes)]
            if code not in placed:
                self.select_code(code)
                return

    def layer_visible(self, layer: str) -> bool:
        check = self.layer_checks.get(layer)
        return True if check is None else check.isChecked()

    def detail_shown(self) -> bool:
        return self.detail_check.isChecked()

    def skin_opacity(self) -> float:
        return self.opacity.value() / 100.0

    def scan_colours(self) -> str:
        """``"own"`` when the scan is to be drawn in its own colours, else ``"distance"``."""
        combo = self.scan_colours_combo
        return "own" if combo.isEnabled() and combo.currentData() == "own" else "distance"

    def set_scan_colours(self, key: str) -> None:
        """Choose ``"own"`` or ``"distance"`` as the user would (ignored while the scan has
        no colours)."""
        index = self.scan_colours_combo.findData(key)
        if index >= 0 and self.scan_colours_combo.isEnabled():
            self.scan_colours_combo.setCurrentIndex(index)

    def _on_scan_colours(self, _index: int) -> None:
        if self._setting_colours:
            return
        self.preferred_scan_colours = self.scan_colours()
        self.scan_colours_changed.emit(self.scan_colours())

    def _show_colour_choice(self, available: bool, tip: str) -> None:
        """Enable the Scan colours box (at the user's last choice) or disable it at
        "distance" with ``tip`` saying why; emits nothing."""
        combo = self.scan_colours_combo
        self._setting_colours = True
        try:
            combo.setEnabled(available)
            key = self.preferred_scan_colours if available else "distance"
            combo.setCurrentIndex(max(0, combo.findData(key)))
            combo.setToolTip(tip)
        finally:
            self._setting_colours = False

    def _on_selection(self) -> None:
        if not self._filling:
            self.selection_changed.emit(self.selected_code())

    # ------------------------------------------------------------ results → widgets
    def set_running(self, running: bool) -> None:
        self.cancel_button.setEnabled(running)
        self.fit_button.setEnabled(not running and bool(self.codes))
        self.save_button.setEnabled(not running and bool(self.codes))
        self.open_button.setEnabled(not running)

    def show_state(self, text: str) -> None:
        self.state_label.setText(text)

    def show_scan(self, scan: OpenedScan | None) -> None:
        if scan is None:
            self.file_label.setText("No scan open.")
            self._show_colour_choice(False, NO_COLOURS_TIP)
            return
        n = scan.mesh.n_faces
        extent = scan.mesh.vertices.max(axis=0) - scan.mesh.vertices.min(axis=0)
        colours = scan.colours
        if colours is not None:
            what = "a texture" if colours.kind == "texture" else "vertex colours"
            self._show_colour_choice(True, f"{COLOURS_TIP}. This scan carries {what}.")
        elif scan.colour_note:
            self._show_colour_choice(
                False, f"This scan's colours could not be read: {scan.colour_note}"
            )
        else:
            self._show_colour_choice(False, NO_COLOURS_TIP)
        carried = {"texture": ", textured", "vertex": ", vertex colours"}
        self.file_label.setText(
            f"{scan.path.name}: {n:,} triangles, "
            f"{' x '.join(f'{v:.0f}' for v in extent)} mm ({scan.factor:g} mm per unit"
            f"{carried.get(colours.kind, '') if colours is not None else ''})"
        )
        if scan.scale is None and self.units_combo.findText(scan.units) >= 0:
            self.units_combo.setCurrentText(scan.units)  # what the scan was read with
        self.codes = list(scan.codes)
        self.set_running(False)

    def show_fit(self, view: FitView | None) -> None:
        if view is None:
            self.figures.setText("Not fitted yet.")
            self.fit_button.setText("Fit")
            return
        self.figures.setText(figures_html(view))
        self.fit_button.setText("Fit again")

    def show_landmarks(
        self,
        codes: tuple[str, ...] | list[str],
        names: Mapping[str, str],
        placed: LandmarkSet,
        guess: Mapping[str, np.ndarray],
        over_holes: frozenset[str],
        to_scan_mm: Mapping[str, float],
        confidence: Mapping[str, float] | None = None,
    ) -> None:
        """Fill the table (the selection is kept)."""
        selected = self.selected_code()
        self._filling = True
        try:
            self.codes = list(codes)
            self.table.setRowCount(len(self.codes))
            for row, code in enumerate(self.codes):
                if code in placed and placed[code].is_defined:
                    state = "placed"
                elif code in guess:
                    state = "over hole" if code in over_holes else "guess"
                else:
                    state = ""
                d = to_scan_mm.get(code)
                c = (confidence or {}).get(code)
                shown = "" if d is None or state == "placed" else f"({d:.1f})"
                if shown and c is not None:
                    shown = f"{c:.2f} {shown}"
                cells = (code, names.get(code, ""), STATE_TEXT.get(state, "—"), shown)
                for col, text in enumerate(cells):
                    item = QTableWidgetItem(text)
                    if col == 3:
                        item.setTextAlignment(Qt.AlignmentFlag.AlignRight)
                    self.table.setItem(row, col, item)
            if selected in self.codes:
                self.table.selectRow(self.codes.index(selected))
        finally:
            self._filling = False
        self.table.resizeColumnToContents(0)
        self.table.resizeColumnToContents(2)
        n = sum(1 for lm in placed if lm.is_defined)
        self.seed_label.setText(
            f"{n} placed: " + ("they seed the next fit." if n >= 3 else "3 or more seed the fit.")
        )
        if self.selected_code() != selected:
            self.selection_changed.emit(self.selected_code())

    def show_history(self, history: CommandStack) -> None:
        """The Undo / Redo buttons follow the window's one undo stack."""
        self.undo_button.setEnabled(history.can_undo)
        self.redo_button.setEnabled(history.can_redo)
        self.undo_button.setToolTip(f"Undo {history.undo_text}" if history.can_undo else "")
        self.redo_button.setToolTip(f"Redo {history.redo_text}" if history.can_redo else "")


def _pct(value: object) -> str:
    return f"{float(value) * 100:.1f} %" if isinstance(value, (int, float)) else "–"


def _mm(value: object) -> str:
    return f"{float(value):.2f} mm" if isinstance(value, (int, float)) else "–"


def figures_html(view: FitView) -> str:
    """The fit's main figures as a small HTML table."""
    fig = view.fit.figures
    lms = fig.get("skin_landmark_to_scan_mm", {}) or {}
    absent = list(lms.get("absent", []))
    orient = fig.get("orientation", {}) or {}
    depths = fig.get("tissue_depths", {}) or {}
    rows: list[tuple[str, str]] = [
        ("Face within 1 mm", _pct(fig.get("face_within_1mm_fraction"))),
        ("Face within 2.5 mm", _pct(fig.get("face_within_2_5mm_fraction"))),
        ("Mean distance", _mm(fig.get("face_mean_distance_mm"))),
        ("Fold-overs", str(fig.get("fold_overs", "–"))),
        (
            "Skin landmarks",
            f"{len(view.guess)} ({len(view.guess) - len(absent)} on the scan, "
            f"{len(absent)} over holes)",
        ),
        ("Landmarks to scan", f"mean {_mm(lms.get('mean'))}, max {_mm(lms.get('max'))}"),
        (
            "Orientation",
            f"{orient.get('method', '–')}"
            + (f", {view.seeds} placed landmarks given" if view.seeds else "")
            + (", mirrored scan" if orient.get("mirrored") else ""),
        ),
    ]
    detail = fig.get("detail")
    if isinstance(detail, dict):
        rows.insert(
            4,
            (
                "Fine detail",
                f"{_pct(detail.get('face_within_1mm_fraction'))} within 1 mm, "
                f"{_pct(detail.get('face_within_2_5mm_fraction'))} within 2.5 mm",
            ),
        )
    colours = view.skin_colours
    if colours is not None:
        source = "texture" if colours.kind == "texture" else "vertex colours"
        rows.append(
            (
                "Skin colour",
                f"{_pct(colours.observed_fraction)} from the scan ({source}), the rest filled",
            )
        )
    user = fig.get("skin_landmark_to_user_mm")
    if isinstance(user, dict):
        rows.append(("To placed landmarks", f"mean {_mm(user.get('mean'))}"))
    if depths:
        rows.append(
            (
                "Tissue depths vs table",
                f"mean |diff| {_mm(depths.get('mean_abs_diff_mm'))} ({depths.get('pairs', 0)} pairs)",
            )
        )
    body = "<tr><td colspan=2><b>Fit</b> (face region, mm)</td></tr>" + "".join(
        f"<tr><td>{k}</td><td>&nbsp;<b>{v}</b></td></tr>" for k, v in rows
    )
    warnings = [*view.fit.warnings, *([escape(view.colour_note)] if view.colour_note else [])]
    notes = "".join(f"<br><i>note: {w}</i>" for w in warnings)
    return f"<table>{body}</table>{notes}"
