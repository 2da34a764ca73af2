"""Dowels dock: depth table, sex and build, and a table of the planned depths.

Every edit is an undoable command on the case's ``dowels`` part
(:class:`~workbench.model.reconstruction_setup.DowelSettings`):
:class:`~workbench.commands.reconstruction_setup.SetDowelSettings` for the
table, sex and build, ``SetDepthOverride`` and ``SetDowelExclusion`` for one
dowel.  The panel follows the part (``changed("dowels")``); the window
re-plans the dowels in a worker and hands the plan back through
:meth:`show_plan`.  Depths are mm from the skull landmark along the dowel
direction.
"""

from __future__ import annotations

from typing import Any

from PySide6.QtCore import Qt
from PySide6.QtWidgets import (
    QAbstractItemView,
    QComboBox,
    QFormLayout,
    QHeaderView,
    QLabel,
    QPushButton,
    QTableWidget,
    QTableWidgetItem,
    QVBoxLayout,
    QWidget,
)

from workbench.commands.reconstruction_setup import (
    SetDepthOverride,
    SetDowelExclusion,
    SetDowelSettings,
)
from workbench.core.errors import WorkbenchError
from workbench.io.tables import list_tables, load_depth_table
from workbench.model.reconstruction_setup import parse_build
from workbench.qt.document import Document
from workbench.qt.panels.build_choice import build_combo, chosen_build, select_build
from workbench.services.reconstruction.case_steps import DowelPreview
from workbench.services.tissue.dowel_sites import site_label

COLUMNS = ("Code", "Table mm", "Depth mm", "Source", "Use")


class DowelsPanel(QWidget):
    """See the module docstring."""

    def __init__(self, document: Document, parent: QWidget | None = None) -> None:
        super().__init__(parent)
        self.document = document
        self._refreshing = False
        self.plan_codes: list[str] = []

        self.table_combo = QComboBox()
        self.table_combo.addItems(list_tables())
        self.table_combo.currentTextChanged.connect(lambda v: self._set("table", v))
        self.sex_combo = QComboBox()
        self.sex_combo.addItems(["male", "female"])
        self.sex_combo.currentTextChanged.connect(lambda v: self._set("sex", v))
        self.build_combo = build_combo()
        self.build_combo.currentIndexChanged.connect(
            lambda _i: self._set("build", chosen_build(self.build_combo))
        )
        form = QFormLayout()
        form.addRow("Depth table", self.table_combo)
        form.addRow("Sex", self.sex_combo)
        form.addRow("Build", self.build_combo)

        self.citation = QLabel("")
        self.citation.setWordWrap(True)
        self.citation.setTextInteractionFlags(Qt.TextInteractionFlag.TextSelectableByMouse)

        self.table = QTableWidget(0, len(COLUMNS))
        self.table.setHorizontalHeaderLabels(list(COLUMNS))
        self.table.verticalHeader().setVisible(False)
        self.table.setSelectionBehavior(QAbstractItemView.SelectionBehavior.SelectRows)
        self.table.horizontalHeader().setSectionResizeMode(3, QHeaderView.ResizeMode.Stretch)
        self.table.itemChanged.connect(self._on_item_changed)
        self.clear_button = QPushButton("Use table depth")
        self.clear_button.setToolTip("Remove the override of the selected dowel")
        self.clear_button.clicked.connect(self.clear_override)
        self.warnings = QLabel("")
        self.warnings.setWordWrap(True)
        self.warnings.setStyleSheet("color: #8a5a00")

        layout = QVBoxLayout(self)
        layout.addLayout(form)
        layout.addWidget(self.citation)
        layout.addWidget(self.table, 1)
        layout.addWidget(self.clear_button)
        layout.addWidget(self.warnings)
        document.case_replaced.connect(self.refresh)
        document.part_changed.connect(self._on_part)
        self.refresh()

    # ------------------------------------------------------------ state → widgets
    def _on_part(self, part: str) -> None:
        if part == "dowels":
            self.refresh()

    def refresh(self) -> None:
        self._refreshing = True
        try:
            dowels = self.document.case.dowels
            table_id = dowels.table
            if self.table_combo.findText(table_id) < 0:
                self.table_combo.addItem(table_id)
            self.table_combo.setCurrentText(table_id)
            self.sex_combo.setCurrentText(dowels.sex)
            select_build(self.build_combo, dowels.build_text)
            self.citation.setText(_citation(table_id))
        finally:
            self._refreshing = False

    def show_plan(self, preview: DowelPreview | None, problem: str = "") -> None:
        """Fill the depth table from a plan (all dowels, excluded ones unticked)."""
        self._refreshing = True
        try:
            dowels = preview.plan.dowels if preview is not None else ()
            self.plan_codes = [d.code for d in dowels]
            self.table.setRowCount(len(dowels))
            for row, d in enumerate(dowels):
                cells = [
                    site_label(d.code),
                    "" if d.table_depth_mm is None else f"{d.table_depth_mm:.1f}",
                    f"{d.depth_mm:.1f}",
                    d.source,
                    "",
                ]
                for col, text in enumerate(cells):
                    item = QTableWidgetItem(text)
                    flags = Qt.ItemFlag.ItemIsSelectable | Qt.ItemFlag.ItemIsEnabled
                    if col == 2:
                        flags |= Qt.ItemFlag.ItemIsEditable
                        item.setToolTip("Type a depth (mm) to override the table")
                    if col == 4:
                        flags |= Qt.ItemFlag.ItemIsUserCheckable
                        item.setCheckState(
                            Qt.CheckState.Unchecked if d.excluded else Qt.CheckState.Checked
                        )
                    item.setFlags(flags)
                    self.table.setItem(row, col, item)
            notes = list(preview.plan.warnings) if preview is not None else []
            self.warnings.setText("\n".join(([problem] if problem else []) + notes))
            if preview is not None and preview.plan.citation:
                self.citation.setText(
                    f"<b>{preview.plan.table_title}</b> — "
                    f"{preview.plan.group_label}<br>{preview.plan.citation}"
                )
        finally:
            self._refreshing = False

    # ------------------------------------------------------------ widgets → commands
    def _set(self, name: str, text: str) -> None:
        """Table, sex or build from a combo box (one undoable command)."""
        if self._refreshing:
            return
        try:
            value: Any = parse_build(text) if name == "build" else text
        except WorkbenchError as exc:
            self.warnings.setText(str(exc))
            return
        if getattr(self.document.case.dowels, name) == value:
            return
        self.document.push(SetDowelSettings(**{name: value}))

    def _on_item_changed(self, item: QTableWidgetItem) -> None:
        if self._refreshing:
            return
        code = self.plan_codes[item.row()]
        if item.column() == 2:
            try:
                depth = float(item.text().replace(",", "."))
            except ValueError:
                depth = float("nan")
            if not depth > 0:
                self.warnings.setText(f"{code}: the depth must be a positive number of mm")
                return
            self.set_depth(code, depth)
        elif item.column() == 4:
            self.set_excluded(code, item.checkState() != Qt.CheckState.Checked)

    def set_depth(self, code: str, depth_mm: float) -> None:
        """Override one dowel's depth (mm, kept to 0.01 mm)."""
        try:
            command = SetDepthOverride(code, round(float(depth_mm), 2))
        except WorkbenchError as exc:
            self.warnings.setText(str(exc))
            return
        self.document.push(command)

    def set_excluded(self, code: str, excluded: bool) -> None:
        """Switch one dowel off (``excluded``) or back on."""
        if (code in self.document.case.dowels.excluded) != bool(excluded):
            self.document.push(SetDowelExclusion(code, bool(excluded)))

    def clear_override(self) -> None:
        rows = self.table.selectionModel().selectedRows()
        if not rows:
            return
        code = self.plan_codes[rows[0].row()]
        if code in self.document.case.dowels.overrides:
            self.document.push(SetDepthOverride(code, None))


def _citation(table_id: str) -> str:
    try:
        table = load_depth_table(table_id)
    except Exception as exc:  # noqa: BLE001 - shown to the user, not raised
        return f"table {table_id}: {exc}"
    sources = table.meta.get("sources", {})
    title = table.meta.get("title", table_id)
    return f"<b>{title}</b><br>" + "<br>".join(str(v) for v in list(sources.values())[:3])
