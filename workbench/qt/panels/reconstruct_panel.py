"""Reconstruct dock: run the fit, skin opacity and colouring, the build slider and the
nose/mouth guides.

The fit runs in a worker (the window's ``reconstruct`` request).  Guides are
listed with their values (mm, head frame: a vertical line fixes x, a
horizontal line y, a lateral point (y, z)); editing a value stores the whole
guide list as the case's ``guides`` part with a
:class:`~workbench.commands.reconstruction_setup.SetGuides` and, with
"Re-fit on change", the window fits again ("Recompute" sets the part back
to None: guides computed from the skull).  Published-rule predictions for the same
features are shown beside them for comparison.

The **build** slider runs over the fit's faces for an unknown body build
(:class:`~workbench.services.reconstruction.build_faces.BuildFaces`: slender, average, heavy,
labelled with their BMI) and emits the build score ``z`` it points at; the
window morphs the drawn face to ``builds.vertices_at(z)`` in place.  The
faces sit at equal steps of the slider; between two of them the score (and
the BMI shown beside the slider) changes linearly.  The slider is **view
state, not a case edit**: it pushes nothing on the undo stack, is not saved
with the case and does not change the saved face, the export or the report,
which stay the *main* build (the case's build, ``--build`` on the command
line).  Each new fit puts it back on the main build.  Without build faces
(``fit.builds is None``) it is disabled, its tooltip says why.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

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
    QSpinBox,
    QTableWidget,
    QTableWidgetItem,
    QVBoxLayout,
    QWidget,
)

from workbench.commands.reconstruction_setup import SetGuides
from workbench.core.errors import WorkbenchError
from workbench.qt.document import Document
from workbench.services.guides.classic import Guide
from workbench.services.reconstruction.case_steps import FitResult, guides_state, user_guides

if TYPE_CHECKING:
    import numpy as np

    from workbench.services.reconstruction.build_faces import BuildFaces

GUIDE_COLUMNS = ("Guide", "Value mm", "On", "Rule")
#: what each kind of guide is, in words (the value's meaning)
GUIDE_KINDS = {
    "vline": "a vertical line in the front view (value: x, mm from the midline)",
    "hline": "a horizontal line in the front view (value: y, mm above the Frankfort plane)",
    "point": "a point in the side view (value: y, z in mm)",
}
FIGURES = (
    ("max_tip_error_mm", "largest dowel-tip error", "mm"),
    ("min_tissue_mm", "thinnest tissue over bone", "mm"),
    ("penetrating_vertices", "skin vertices inside bone", ""),
    ("refits", "non-penetration refits", ""),
    ("seconds", "fit time", "s"),
)
#: the colouring combo's entries (see :attr:`ReconstructPanel.colouring_changed`)
COLOURINGS = ("skin", "spread", "band")
#: the colour bar title of the "band" colouring ("95 % band half-width mm" on two lines: on
#: one it ran past the view's right edge)
BAND_TITLE = "95 % band\nhalf-width mm"
#: build slider steps between two neighbouring build faces
BUILD_STEPS = 100
BUILD_TIP = (
    "Body build of the face shown (view only: not a case edit, no undo step; the saved "
    "face, export and report stay the main build, the case's build / --build)"
)
NO_FIT_TIP = "Reconstruct the face first: the build slider morphs the fitted face."
NO_BUILDS_TIP = (
    "One face only: this fit's tissue depths cannot vary with body build (a uniform "
    "mean + k SD, a table's build group, a table without SDs or the reference's own "
    "tissue), so there are no slender/heavy faces to morph between."
)
CONSENSUS_TIP = (
    "One face only: a library consensus (the per-vertex median of several reference "
    "heads) has no build faces to morph between."
)


class ReconstructPanel(QWidget):
    """See the module docstring.

    Signals
    -------
    reconstruct_requested()
    accept_held_requested(), discard_held_requested()
        Apply or drop a refit held back because it would change the face where no edit was.
    opacity_changed(float)
    colouring_changed(str)
        "skin", "spread" (the ensemble's spread) or "band" (the 95 % band's half-width).
    build_changed(float)
        The build slider moved (by the user or :meth:`set_build`): the build score ``z``
        to show (between the fit's slender and heavy faces).  View state only: nothing is
        pushed on the document's stack (see the module docstring).
    """

    reconstruct_requested = Signal()
    #: the user's answer about a refit held back (see :meth:`show_held`)
    accept_held_requested = Signal()
    discard_held_requested = Signal()
    opacity_changed = Signal(float)
    colouring_changed = Signal(str)
    build_changed = Signal(float)

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
        self.colouring.addItems(list(COLOURINGS))
        self.colouring.setToolTip(
            "spread: per-vertex RMS spread of the ensemble (mm)\n"
            "band: half-width of the 95 % band holding the true skin when the build is "
            "unknown (mm)"
        )
        self.colouring.currentTextChanged.connect(self.colouring_changed.emit)
        self.opacity = QSlider(Qt.Orientation.Horizontal)
        self.opacity.setRange(0, 100)
        self.opacity.setValue(60)
        self.opacity.setToolTip("Skin opacity (%); the same as the Layers dock's face slider")
        self.opacity.valueChanged.connect(lambda v: self.opacity_changed.emit(v / 100.0))
        # a refit held back (it would turn the face or move it away from the edit): the
        # user decides; hidden while there is none
        self.held_note = QLabel()
        self.held_note.setWordWrap(True)
        self.held_note.setStyleSheet("color: #8a4b00;")
        self.accept_held = QPushButton("Apply the new face")
        self.accept_held.clicked.connect(self.accept_held_requested.emit)
        self.discard_held = QPushButton("Keep the previous face")
        self.discard_held.clicked.connect(self.discard_held_requested.emit)
        form = QFormLayout()
        form.addRow(self.run_button)
        form.addRow(self.held_note)
        form.addRow(self.accept_held, self.discard_held)
        self.show_held(None)
        form.addRow(self.use_guides)
        form.addRow(self.auto_refit)
        form.addRow("Ensemble fits", self.ensemble)
        form.addRow("Colour", self.colouring)
        form.addRow("Skin opacity", self.opacity)
        self._builds: BuildFaces | None = None
        build_box = self._make_build_slider()

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
        layout.addWidget(build_box)
        layout.addWidget(QLabel("<b>Guides</b> (head frame, mm)"))
        layout.addWidget(self.guide_table, 1)
        row = QHBoxLayout()
        row.addWidget(self.reset_guides)
        layout.addLayout(row)
        layout.addWidget(QLabel("<b>Published predictions</b>"))
        layout.addWidget(self.predictions)
        layout.addWidget(self.figures)
        document.part_changed.connect(self._on_part)

    def show_held(self, reason: str | None) -> None:
        """Say why a refit was held back and offer to apply or drop it (None: hide)."""
        held = reason is not None
        self.held_note.setText(f"The new face was not applied: {reason}." if held else "")
        for widget in (self.held_note, self.accept_held, self.discard_held):
            widget.setVisible(held)

    def _make_build_slider(self) -> QWidget:
        """The build row: "Build", the slider and the current BMI; the faces' labels below."""
        self.build_slider = QSlider(Qt.Orientation.Horizontal)
        self.build_slider.setRange(0, 2 * BUILD_STEPS)
        self.build_slider.setSingleStep(BUILD_STEPS // 20)
        self.build_slider.setPageStep(BUILD_STEPS)  # Page Up/Down: face to face
        self.build_slider.setTickPosition(QSlider.TickPosition.TicksBelow)
        self.build_slider.setTickInterval(BUILD_STEPS)
        self.build_slider.valueChanged.connect(self._on_build_moved)
        self.build_value = QLabel("")
        self.build_value.setMinimumWidth(
            self.build_value.fontMetrics().horizontalAdvance("BMI 00.0")
        )
        self.build_value.setAlignment(Qt.AlignmentFlag.AlignRight | Qt.AlignmentFlag.AlignVCenter)
        self.build_box = QWidget()
        grid = QGridLayout(self.build_box)
        grid.setContentsMargins(0, 4, 0, 4)
        grid.setVerticalSpacing(0)
        grid.addWidget(QLabel("Build"), 0, 0)
        grid.addWidget(self.build_slider, 0, 1)
        grid.addWidget(self.build_value, 0, 2)
        grid.setColumnStretch(1, 1)
        # the faces' labels under the slider's track: the first at its left end, the last
        # at its right end, the others centred on their tick
        self.build_ticks = QWidget()
        self._tick_grid = QGridLayout(self.build_ticks)
        self._tick_grid.setContentsMargins(0, 0, 0, 0)
        self._tick_grid.setHorizontalSpacing(0)
        self.build_labels: list[QLabel] = []
        grid.addWidget(self.build_ticks, 1, 1)
        self.show_builds(None)
        return self.build_box

    # ------------------------------------------------------------ results → widgets
    def show_builds(self, builds: BuildFaces | None, why: str = NO_FIT_TIP) -> None:
        """Set the build slider up for ``builds`` (None: disabled, tooltip ``why``), on its
        main build, without emitting :attr:`build_changed` (the face drawn next is that
        build)."""
        self._builds = builds
        for label in self.build_labels:
            self._tick_grid.removeWidget(label)
            label.deleteLater()
        self.build_labels = []
        blocked = self.build_slider.blockSignals(True)
        try:
            if builds is None:
                self.build_slider.setValue(self.build_slider.maximum() // 2)
                self.build_slider.setEnabled(False)
                self.build_value.setText("" if why == NO_FIT_TIP else "one face")
                self.build_box.setToolTip(why)
                self.build_slider.setToolTip(why)
                self.build_ticks.setVisible(False)
                return
            n = len(builds.names)
            self.build_slider.setRange(0, (n - 1) * BUILD_STEPS)
            for i, name in enumerate(builds.names):
                # "slender (BMI 19)" on two lines: on one, three of them overran the track
                label = QLabel(f"{name}\n(BMI {_bmi(builds.bmi[name])})")
                label.setToolTip(f"build score z = {builds.z[name]:+.2f}")
                if i == 0:
                    align = Qt.AlignmentFlag.AlignLeft
                    self._tick_grid.addWidget(label, 0, 0, 1, 1, align)
                elif i == n - 1:
                    align = Qt.AlignmentFlag.AlignRight
                    self._tick_grid.addWidget(label, 0, 2 * i - 1, 1, 1, align)
                else:  # spans the two half-columns either side of its tick
                    align = Qt.AlignmentFlag.AlignHCenter
                    self._tick_grid.addWidget(label, 0, 2 * i - 1, 1, 2, align)
                label.setAlignment(align | Qt.AlignmentFlag.AlignTop)
                self.build_labels.append(label)
            for c in range(2 * (n - 1)):
                self._tick_grid.setColumnStretch(c, 1)
            self.build_slider.setValue(round(self._position_of(builds.main_z)))
            self.build_slider.setEnabled(True)
            self.build_box.setToolTip("")
            self.build_slider.setToolTip(BUILD_TIP)
            self.build_ticks.setVisible(True)
            self._show_build_value()
        finally:
            self.build_slider.blockSignals(blocked)

    def build_z(self) -> float | None:
        """The build score the slider points at (None without build faces)."""
        builds = self._builds
        if builds is None:
            return None
        position = self.build_slider.value()
        if position == round(self._position_of(builds.main_z)):
            return builds.main_z  # the main face exactly (a main BMI between two ticks)
        return self._z_at(position)

    def build_position(self, name: str) -> int:
        """The slider position of build face ``name`` (a name of ``builds.names``)."""
        if self._builds is None:
            raise ValueError("no build faces: the slider is disabled")
        return self._builds.names.index(name) * BUILD_STEPS

    def set_build(self, name: str) -> None:
        """Move the slider to build face ``name`` (emits :attr:`build_changed` if it moves)."""
        self.build_slider.setValue(self.build_position(name))

    def _z_at(self, position: float) -> float:
        """The build score at slider ``position`` (faces at equal steps, linear between)."""
        builds = self._builds
        if builds is None:
            raise ValueError("no build faces")
        return _interp(position, _ticks(builds), [builds.z[n] for n in builds.names])

    def _position_of(self, z: float) -> float:
        builds = self._builds
        if builds is None:
            raise ValueError("no build faces")
        return _interp(z, [builds.z[n] for n in builds.names], _ticks(builds))

    def _show_build_value(self) -> None:
        builds = self._builds
        if builds is None:
            return
        position = self.build_slider.value()
        bmi = _interp(position, _ticks(builds), [builds.bmi[n] for n in builds.names])
        self.build_value.setText(f"BMI {bmi:.1f}")
        at = position // BUILD_STEPS if position % BUILD_STEPS == 0 else None
        self.build_value.setToolTip(
            f"{builds.names[at]} face" if at is not None else "between two build faces (a blend)"
        )

    def _on_build_moved(self, _value: int) -> None:
        if self._builds is None:
            return
        self._show_build_value()
        z = self.build_z()
        if z is not None:
            self.build_changed.emit(z)

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
            cells = [g.label, value, "", g.rule_id]
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
                item.setToolTip(
                    f"{g.label}: {GUIDE_KINDS.get(g.kind, g.kind)}\n{g.citation}\n"
                    f"{g.derivation}\nsource: {g.source}"
                )
                self.guide_table.setItem(row, col, item)

    def show_result(self, fit: FitResult | None) -> None:
        self._refreshing = True
        try:
            self._show_guides(list(fit.guides) if fit is not None else [])
            self._show_check(fit)
            # (getattr: stand-ins for a FitResult in tests carry only the older fields)
            builds = getattr(fit, "builds", None)
            why = NO_FIT_TIP if fit is None else NO_BUILDS_TIP
            if getattr(fit, "references", None) is not None:
                why = CONSENSUS_TIP
            self.show_builds(builds, why)
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


def _bmi(value: float) -> str:
    """A BMI for a label: one decimal, none when whole ("19", "24.3")."""
    return f"{round(float(value), 1):g}"


def _ticks(builds: BuildFaces) -> list[float]:
    """The slider positions of the build faces (thinnest first)."""
    return [float(i * BUILD_STEPS) for i in range(len(builds.names))]


def _interp(x: float, xs: list[float], ys: list[float]) -> float:
    """Piecewise-linear ``ys`` at ``x`` (``xs`` increasing), clamped at the ends."""
    import numpy as np

    return float(np.interp(x, xs, ys))


def _median(values: np.ndarray) -> float:
    import numpy as np

    return float(np.median(values))
