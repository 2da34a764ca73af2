"""Reconstruct dock: run the fit, skin opacity and colouring, and the nose/mouth guides.

The fit runs in a worker (the window's ``reconstruct`` request).  Guides are
listed with their values (mm, head frame: a vertical line fixes x, a
horizontal line y, a lateral point (y, z)); editing a value stores the whole
guide list as the case's ``guides`` part with a
:class:`~workbench.commands.reconstruction_setup.SetGuides` and, with
"Re-fit on change", the window fits again ("Recompute" sets the part back
to None: guides computed from the skull).  Published-rule predictions for the same
features are shown beside them for comparison.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from PySide6.QtCore import Qt, Signal
from PySide6.QtWidgets import (
    QAbstractItemView,
    QCheckBox,
    QComboBox,
    QFormLayout,
    QHBoxLayout,
    QHeaderView,
    QLabel,
    QPushButton,
    QSlider,
    QSpinBox,
    QTableWidget,
    QTableWidgetItem,
    QVBoxLayout,
    QWidget,
)

from workbench.commands.reconstruction_setup import SetGuides
from workbench.core.errors import WorkbenchError
from workbench.qt.document import Document
from workbench.qt.jobs import FitResult, guides_state, user_guides
from workbench.services.guides import Guide

if TYPE_CHECKING:
    import numpy as np

GUIDE_COLUMNS = ("Guide", "Value mm", "On", "Rule")
FIGURES = (
    ("max_tip_error_mm", "largest dowel-tip error", "mm"),
    ("min_tissue_mm", "thinnest tissue over bone", "mm"),
    ("penetrating_vertices", "skin vertices inside bone", ""),
    ("refits", "non-penetration refits", ""),
    ("seconds", "fit time", "s"),
)


class ReconstructPanel(QWidget):
    """See the module docstring.

    Signals
    -------
    reconstruct_requested()
    opacity_changed(float)
    colouring_changed(str)
        "skin" or "spread".
    """

    reconstruct_requested = Signal()
    opacity_changed = Signal(float)
    colouring_changed = Signal(str)

    def __init__(self, document: Document, parent: QWidget | None = None) -> None:
        super().__init__(parent)
        self.document = document
        self.guides: list = []
        self._refreshing = False

        self.run_button = QPushButton("Reconstruct face")
        self.run_button.setToolTip("Fit the reference head to the dowel tips (Ctrl+R)")
        self.run_button.clicked.connect(self.reconstruct_requested.emit)
        self.use_guides = QCheckBox("Use nose and mouth guides")
        self.use_guides.setChecked(True)
        self.auto_refit = QCheckBox("Re-fit on change")
        self.auto_refit.setChecked(True)
        self.ensemble = QSpinBox()
        self.ensemble.setRange(0, 50)
        self.ensemble.setToolTip("Number of fits drawing depths from mean ± SD (0 = off)")
        self.colouring = QComboBox()
        self.colouring.addItems(["skin", "spread"])
        self.colouring.setToolTip("spread: per-vertex RMS spread of the ensemble (mm)")
        self.colouring.currentTextChanged.connect(self.colouring_changed.emit)
        self.opacity = QSlider(Qt.Orientation.Horizontal)
        self.opacity.setRange(0, 100)
        self.opacity.setValue(60)
        self.opacity.setToolTip("Skin opacity (%); the same as the Layers dock's face slider")
        self.opacity.valueChanged.connect(lambda v: self.opacity_changed.emit(v / 100.0))
        form = QFormLayout()
        form.addRow(self.run_button)
        form.addRow(self.use_guides)
        form.addRow(self.auto_refit)
        form.addRow("Ensemble fits", self.ensemble)
        form.addRow("Colour", self.colouring)
        form.addRow("Skin opacity", self.opacity)

        self.guide_table = QTableWidget(0, len(GUIDE_COLUMNS))
        self.guide_table.setHorizontalHeaderLabels(list(GUIDE_COLUMNS))
        self.guide_table.verticalHeader().setVisible(False)
        self.guide_table.setSelectionBehavior(QAbstractItemView.SelectionBehavior.SelectRows)
        self.guide_table.horizontalHeader().setSectionResizeMode(0, QHeaderView.ResizeMode.Stretch)
        self.guide_table.itemChanged.connect(self._on_guide_edited)
        self.reset_guides = QPushButton("Recompute guides from the skull")
        self.reset_guides.clicked.connect(self.recompute_guides)
        self.predictions = QLabel("")
        self.predictions.setWordWrap(True)
        self.figures = QLabel("Not fitted yet.")
        self.figures.setWordWrap(True)
        # the registration's self-check (issue 28): a doubted face says so above everything
        # for as long as it is the face shown, not only in the status line a later action
        # overwrites
        self.check_banner = QLabel("")
        self.check_banner.setWordWrap(True)
        self.check_banner.setStyleSheet(
            "QLabel { color: white; background: #b3261e; padding: 6px; font-weight: bold; }"
        )
        self.check_banner.setVisible(False)

        layout = QVBoxLayout(self)
        layout.addWidget(self.check_banner)
        layout.addLayout(form)
        layout.addWidget(QLabel("<b>Guides</b> (head frame, mm)"))
        layout.addWidget(self.guide_table, 1)
        row = QHBoxLayout()
        row.addWidget(self.reset_guides)
        layout.addLayout(row)
        layout.addWidget(QLabel("<b>Published predictions</b>"))
        layout.addWidget(self.predictions)
        layout.addWidget(self.figures)
        document.part_changed.connect(self._on_part)

    # ------------------------------------------------------------ results → widgets
    def show_opacity(self, value: float) -> None:
        """Show the scene's skin opacity (0–1) on the slider without emitting it back."""
        blocked = self.opacity.blockSignals(True)
        try:
            self.opacity.setValue(round(float(value) * 100))
        finally:
            self.opacity.blockSignals(blocked)

    def _on_part(self, part: str) -> None:
        """The case's guides changed (an edit, undo, redo): list the stored ones.

        When the part goes back to None (computed guides), the list stays
        until the next fit computes them.
        """
        stored = self.document.case.guides
        if part != "guides" or stored is None or stored == guides_state(self.guides):
            return  # (the list shown is what was just stored: an edit in this table)
        try:
            guides = user_guides(self.document.case)
        except WorkbenchError as exc:
            self.figures.setText(f"stored guides not usable: {exc}")
            return
        self._refreshing = True
        try:
            self._show_guides(guides or [])
        finally:
            self._refreshing = False

    def _show_guides(self, guides: list[Guide]) -> None:
        self.guides = list(guides)
        self.guide_table.setRowCount(len(self.guides))
        for row, g in enumerate(self.guides):
            value = ", ".join(f"{v:.1f}" for v in g.value)
            cells = [f"{g.label} [{g.kind}]", value, "", g.rule_id]
            for col, text in enumerate(cells):
                item = QTableWidgetItem(text)
                flags = Qt.ItemFlag.ItemIsSelectable | Qt.ItemFlag.ItemIsEnabled
                if col == 1:
                    flags |= Qt.ItemFlag.ItemIsEditable
                if col == 2:
                    flags |= Qt.ItemFlag.ItemIsUserCheckable
                    item.setCheckState(
                        Qt.CheckState.Checked if g.enabled else Qt.CheckState.Unchecked
                    )
                item.setFlags(flags)
                item.setToolTip(f"{g.citation}\n{g.derivation}\nsource: {g.source}")
                self.guide_table.setItem(row, col, item)

    def show_result(self, fit: FitResult | None) -> None:
        self._refreshing = True
        try:
            self._show_guides(list(fit.guides) if fit is not None else [])
            self._show_check(fit)
            if fit is None:
                self.figures.setText("Not fitted yet.")
                self.predictions.setText("")
                return
            figs = fit.recon.figures
            lines = [f"{label}: {_num(figs.get(key))} {unit}" for key, label, unit in FIGURES]
            if fit.spread is not None:
                lines.append(
                    f"ensemble spread: median {_num(float(_median(fit.spread)))} mm, "
                    f"max {_num(float(fit.spread.max()))} mm"
                )
            lines += [f"note: {w}" for w in fit.warnings]
            self.figures.setText("\n".join(lines))
            self.predictions.setText(
                "\n".join(
                    f"{p.label}: {p.quantity} {p.value_mm:.1f} mm" for p in fit.predictions[:8]
                )
            )
        finally:
            self._refreshing = False

    # ------------------------------------------------------------ widgets → commands
    def _show_check(self, fit: FitResult | None) -> None:
        """The red CHECK banner when the fit's registration asks for a check, else none."""
        reg = None if fit is None else fit.recon.registration
        check = {} if reg is None else reg.figures.get("self_check") or {}
        reasons = list(check.get("reasons", ()))
        doubted = check.get("outcome") == "check"
        self.check_banner.setText(
            "CHECK before use: " + "; ".join(reasons or ["the registration's self-check"])
            if doubted
            else ""
        )
        self.check_banner.setVisible(doubted)

    def _on_guide_edited(self, item: QTableWidgetItem) -> None:
        if self._refreshing or not self.guides:
            return
        row = item.row()
        g = self.guides[row]
        if item.column() == 1:
            try:
                value = tuple(float(t) for t in item.text().replace(";", ",").split(","))
            except ValueError:
                value = ()
            if len(value) != len(g.value):
                self.figures.setText(f"{g.label}: give {len(g.value)} number(s) in mm")
                return
            self.set_guide(row, value=value)
        elif item.column() == 2:
            self.set_guide(row, enabled=item.checkState() == Qt.CheckState.Checked)

    def set_guide(
        self, row: int, value: tuple[float, ...] | None = None, enabled: bool | None = None
    ) -> None:
        """Move (or switch) guide ``row`` and store the guide list in the case."""
        from dataclasses import replace

        g = self.guides[row]
        new = g.moved(value) if value is not None else g
        if enabled is not None:
            new = replace(new, enabled=enabled)
        guides = list(self.guides)
        guides[row] = new
        self.guides = guides
        what = "Move" if value is not None else ("Use" if enabled else "Switch off")
        self.document.push(SetGuides(guides_state(guides), label=f"{what} guide {g.id}"))

    def recompute_guides(self) -> None:
        if self.document.case.guides is not None:
            self.document.push(SetGuides(None, label="Recompute guides"))


def _num(value: object) -> str:
    if value is None:
        return "–"
    if isinstance(value, float):
        return f"{value:.2f}"
    return str(value)


def _median(values: np.ndarray) -> float:
    import numpy as np

    return float(np.median(values))
