"""Compare dock: a true skin surface against the reconstruction.

Signed distance from each true-skin vertex to the reconstructed face
(mm; positive = the reconstruction lies outside the true skin, i.e. too much
tissue), computed by :func:`workbench.services.validation.compare.compare_surfaces` in
a worker.  The true skin must be in the skull file's frame and mm.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from PySide6.QtCore import Signal
from PySide6.QtWidgets import (
    QHeaderView,
    QLabel,
    QPushButton,
    QTableWidget,
    QTableWidgetItem,
    QVBoxLayout,
    QWidget,
)

if TYPE_CHECKING:
    from workbench.services.validation.compare import Comparison

FIGURE_ROWS = (
    ("mean_abs_mm", "mean |distance|", "mm"),
    ("rms_mm", "RMS", "mm"),
    ("signed_mean_mm", "mean signed", "mm"),
    ("pct_within_2_5mm", "within 2.5 mm", "%"),
    ("pct_within_5mm", "within 5 mm", "%"),
    ("coverage", "coverage", ""),
    ("n_vertices", "vertices compared", ""),
)


class ComparePanel(QWidget):
    """See the module docstring.

    Signals
    -------
    load_requested()
    """

    load_requested = Signal()

    def __init__(self, parent: QWidget | None = None) -> None:
        super().__init__(parent)
        self.load_button = QPushButton("Load true skin surface…")
        self.load_button.clicked.connect(self.load_requested.emit)
        self.source = QLabel("No true skin loaded.")
        self.source.setWordWrap(True)
        self.table = QTableWidget(0, 3)
        self.table.setHorizontalHeaderLabels(["Region / figure", "value", ""])
        self.table.verticalHeader().setVisible(False)
        self.table.horizontalHeader().setSectionResizeMode(0, QHeaderView.ResizeMode.Stretch)
        self.notes = QLabel("")
        self.notes.setWordWrap(True)
        layout = QVBoxLayout(self)
        layout.addWidget(self.load_button)
        layout.addWidget(self.source)
        layout.addWidget(self.table, 1)
        layout.addWidget(self.notes)

    def show_comparison(self, name: str, comparison: Comparison | None) -> None:
        """Figures of a :class:`~workbench.services.validation.compare.Comparison` (None clears)."""
        if comparison is None:
            self.table.setRowCount(0)
            self.source.setText(
                f"{name}: waiting for a reconstruction" if name else "No true skin loaded."
            )
            return
        self.source.setText(
            f"True skin: {name}<br>positive = reconstruction outside the "
            "true skin (too much tissue)"
        )
        figs = comparison.figures
        rows = [(label, figs.get(key), unit) for key, label, unit in FIGURE_ROWS]
        for region, f in comparison.regions.items():
            rows.append((f"{region}: mean |d|", f.get("mean_abs_mm"), "mm"))
        self.table.setRowCount(len(rows))
        for i, (label, value, unit) in enumerate(rows):
            text = (
                "–"
                if value is None
                else (f"{value:.2f}" if isinstance(value, float) else str(value))
            )
            for col, cell in enumerate((label, text, unit)):
                self.table.setItem(i, col, QTableWidgetItem(cell))
        self.notes.setText("\n".join(comparison.notes))
