"""Animate dock: presets, muscle sliders, jaw, gaze, lids, Relax and a track timeline.

Widgets and signals only; :class:`workbench.qt.tools.animate.tool.AnimateTool`
drives the :class:`workbench.services.animation.animator.Animator` and the 3D view,
and hands the animator's state back through :meth:`AnimatePanel.show_state`
and the timeline's through :meth:`AnimatePanel.show_timeline`.
Contractions are 0..1 (slider 0..100 %), the jaw in degrees (positive
opens), gaze in degrees (yaw toward the subject's left, pitch up, within
the service's ``GAZE_RANGE_DEG``), lids 0 (open) .. 1 (closed) (slider
0..100 %).  The timeline's slider is the frame index of the loaded track.
These controls are view state: nothing here edits the case.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping

from PySide6.QtCore import Qt, Signal
from PySide6.QtWidgets import (
    QCheckBox,
    QComboBox,
    QDoubleSpinBox,
    QFormLayout,
    QGridLayout,
    QGroupBox,
    QHBoxLayout,
    QLabel,
    QPushButton,
    QSlider,
    QToolButton,
    QVBoxLayout,
    QWidget,
)

from workbench.services.animation.animator import GAZE_RANGE_DEG, expression_label

#: head chooser entries: title → reference head sex
HEADS = {"Reference male": "male", "Reference female": "female"}
#: the case's own head, offered once the face is fitted (the tool's key for it)
RECONSTRUCTION = "This case's reconstruction"
RECONSTRUCTION_KEY = "reconstruction"
#: the session's own heads (the tool's key → the list's title), offered while they exist:
#: the reconstruction, the head fitted to a scan (Fit scan dock), the aged head (Age dock)
SESSION_HEADS = {
    RECONSTRUCTION_KEY: RECONSTRUCTION,
    "scan": "The fitted scan",
    "aged": "The aged head",
}
#: jaw slider range (degrees; the service allows more, 20° is a wide-open mouth)
JAW_MAX_DEG = 20.0
#: gaze slider range (degrees either way; the service's GAZE_RANGE_DEG)
GAZE_MAX_DEG = int(GAZE_RANGE_DEG)
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
    gaze_changed(float, float) yaw (toward the subject's left) and pitch (up), degrees
    lids_changed(float)        lid closure 0 (open) .. 1 (closed)
    relax_requested()
    bones_toggled(bool)        show the skull and teeth under a translucent skin
    open_track_requested()     "Open track…" clicked (the tool asks for the file)
    save_track_requested()     "Save track…" clicked
    record_requested()         "Record keyframe": the current pose as a key at the current time
    frame_requested(int)       the timeline slider moved to this frame (by the user)
    play_toggled(bool)         Play (True) / Pause (False)
    loop_toggled(bool)
    length_changed(float)      the track's duration (seconds) edited
    """

    head_changed = Signal(str)
    expression_changed = Signal(str, float)
    muscle_changed = Signal(str, float)
    jaw_changed = Signal(float)
    gaze_changed = Signal(float, float)
    lids_changed = Signal(float)
    relax_requested = Signal()
    bones_toggled = Signal(bool)
    open_track_requested = Signal()
    save_track_requested = Signal()
    record_requested = Signal()
    frame_requested = Signal(int)
    play_toggled = Signal(bool)
    loop_toggled = Signal(bool)
    length_changed = Signal(float)

    def __init__(self, expressions: Iterable[str] = (), parent: QWidget | None = None) -> None:
        super().__init__(parent)
        self._quiet = False
        layout = QVBoxLayout(self)
        intro = QLabel(
            "Move a reference head's face: presets, single muscles, the jaw, gaze and "
            "lids, or play a keyframe track. "
            "View only: the case is not changed."
        )
        intro.setWordWrap(True)
        layout.addWidget(intro)

        form = QFormLayout()
        self.head = QComboBox()
        self.head.addItems(list(HEADS))
        self.head.currentTextChanged.connect(lambda _t: self.head_changed.emit(self.sex()))
        form.addRow("Head", self.head)
        self.expression = QComboBox()
        for name in expressions:  # shown with its action units; the name is the item's data
            self.expression.addItem(expression_label(name), name)
        self.expression.setToolTip(
            "FACS-based presets (EMFACS prototypes of the six basic emotions) and single "
            "action units (AU, Ekman, Friesen & Hager 2002)"
        )
        self.expression.currentIndexChanged.connect(lambda _i: self._emit_expression())
        form.addRow("Expression", self.expression)
        self.intensity, self.intensity_value = _slider(100, 100)
        self.intensity.valueChanged.connect(lambda _v: self._emit_expression())
        form.addRow("Intensity", _row(self.intensity, self.intensity_value))
        self.jaw, self.jaw_value = _slider(int(JAW_MAX_DEG * 10), 0, unit="°", scale=0.1)
        self.jaw.valueChanged.connect(self._emit_jaw)
        form.addRow("Jaw opening", _row(self.jaw, self.jaw_value))
        self.gaze_yaw, self.gaze_yaw_value = _slider(
            GAZE_MAX_DEG, 0, unit="°", minimum=-GAZE_MAX_DEG
        )
        self.gaze_yaw.setToolTip("Eyes turned toward the subject's left (+) or right (−)")
        self.gaze_yaw.valueChanged.connect(lambda _v: self._emit_gaze())
        form.addRow("Gaze left/right", _row(self.gaze_yaw, self.gaze_yaw_value))
        self.gaze_pitch, self.gaze_pitch_value = _slider(
            GAZE_MAX_DEG, 0, unit="°", minimum=-GAZE_MAX_DEG
        )
        self.gaze_pitch.setToolTip("Eyes turned up (+) or down (−)")
        self.gaze_pitch.valueChanged.connect(lambda _v: self._emit_gaze())
        form.addRow("Gaze up/down", _row(self.gaze_pitch, self.gaze_pitch_value))
        self.lids, self.lids_value = _slider(100, 0)
        self.lids.setToolTip("Eyelid closure: 0 % open, 100 % closed")
        self.lids.valueChanged.connect(self._emit_lids)
        form.addRow("Lids closed", _row(self.lids, self.lids_value))
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
        layout.addWidget(self._timeline_box())

        self._muscle_box = QWidget()
        self._muscle_layout = QVBoxLayout(self._muscle_box)
        self._muscle_layout.setContentsMargins(0, 0, 0, 0)
        layout.addWidget(self._muscle_box)
        layout.addStretch(1)
        self.muscles: dict[str, QSlider] = {}
        self._muscle_values: dict[str, QLabel] = {}

    def _timeline_box(self) -> QGroupBox:
        box = QGroupBox("Timeline")
        grid = QVBoxLayout(box)
        files = QHBoxLayout()
        self.open_track = QPushButton("Open track…")
        self.open_track.setToolTip(
            "A JSON keyframe/phoneme track (the format of `workbench animate --track`)"
        )
        self.open_track.clicked.connect(self.open_track_requested)
        files.addWidget(self.open_track)
        self.record = QPushButton("Record keyframe")
        self.record.setToolTip(
            "Add the current pose (sliders, jaw, gaze, lids) as a key at the current time"
        )
        self.record.clicked.connect(self.record_requested)
        files.addWidget(self.record)
        self.save_track = QPushButton("Save track…")
        self.save_track.setEnabled(False)
        self.save_track.clicked.connect(self.save_track_requested)
        files.addWidget(self.save_track)
        files.addStretch(1)
        grid.addLayout(files)
        self.track_label = QLabel("No track: open one, or record keyframes.")
        self.track_label.setWordWrap(True)
        grid.addWidget(self.track_label)
        transport = QHBoxLayout()
        self.play = QToolButton()
        self.play.setText("Play")
        self.play.setCheckable(True)
        self.play.setEnabled(False)
        self.play.toggled.connect(self._play_clicked)
        transport.addWidget(self.play)
        self.frame = QSlider(Qt.Orientation.Horizontal)
        self.frame.setRange(0, 0)
        self.frame.setEnabled(False)
        self.frame.setToolTip("Scrub: the frame of the track shown")
        self.frame.valueChanged.connect(self._emit_frame)
        transport.addWidget(self.frame, 1)
        self.loop = QCheckBox("Loop")
        self.loop.toggled.connect(self.loop_toggled)
        transport.addWidget(self.loop)
        grid.addLayout(transport)
        times = QHBoxLayout()
        self.time_label = QLabel("0.00 s")
        times.addWidget(self.time_label, 1)
        times.addWidget(QLabel("Length"))
        self.length = QDoubleSpinBox()
        self.length.setRange(0.1, 600.0)
        self.length.setDecimals(2)
        self.length.setSingleStep(0.5)
        self.length.setSuffix(" s")
        self.length.setValue(2.0)
        self.length.setKeyboardTracking(False)
        self.length.setToolTip("The track's duration (a new track for recording keys if none)")
        self.length.valueChanged.connect(self._emit_length)
        times.addWidget(self.length)
        grid.addLayout(times)
        self.track_message = QLabel("")
        self.track_message.setWordWrap(True)
        self.track_message.setStyleSheet("color: #b00020;")
        self.track_message.setTextInteractionFlags(Qt.TextInteractionFlag.TextSelectableByMouse)
        self.track_message.hide()
        grid.addWidget(self.track_message)
        return box

    # ------------------------------------------------------------ reading
    def sex(self) -> str:
        """The head to animate: ``"male"``, ``"female"`` (the reference heads) or
        ``"reconstruction"`` (the case's fitted head)."""
        key = self.head.currentData()
        if isinstance(key, str):  # one of the session's heads
            return key
        return HEADS.get(self.head.currentText(), "male")

    def offer_head(self, key: str, on: bool, title: str | None = None) -> None:
        """List one of the session's heads (:data:`SESSION_HEADS`) while it exists, under
        ``title`` (e.g. "The aged head (8 y)"), or take it off the list."""
        index = self.head.findData(key)
        title = title or SESSION_HEADS[key]
        if on and index < 0:
            self.head.addItem(title, key)
        elif on:
            self.head.setItemText(index, title)
        elif index >= 0:
            if self.head.currentIndex() == index:
                self.head.setCurrentIndex(0)
            self.head.removeItem(index)

    def offer_reconstruction(self, on: bool) -> None:
        """List the case's reconstruction among the heads (once a face is fitted) or not."""
        self.offer_head(RECONSTRUCTION_KEY, on)

    def weight(self) -> float:
        return self.intensity.value() / 100.0

    def _emit_jaw(self, value: int) -> None:
        if not self._quiet:
            self.jaw_changed.emit(value / 10.0)

    def gaze(self) -> tuple[float, float]:
        """(yaw, pitch) in degrees as the sliders show them."""
        return float(self.gaze_yaw.value()), float(self.gaze_pitch.value())

    def _emit_gaze(self) -> None:
        if not self._quiet:
            self.gaze_changed.emit(*self.gaze())

    def _emit_lids(self, value: int) -> None:
        if not self._quiet:
            self.lids_changed.emit(value / 100.0)

    def _emit_frame(self, value: int) -> None:
        if not self._quiet:
            self.frame_requested.emit(value)

    def _emit_length(self, value: float) -> None:
        if not self._quiet:
            self.length_changed.emit(float(value))

    def _play_clicked(self, on: bool) -> None:
        self.play.setText("Pause" if on else "Play")
        if not self._quiet:
            self.play_toggled.emit(on)

    def _emit_muscle(self, code: str, value: int) -> None:
        if not self._quiet:
            self.muscle_changed.emit(code, value / 100.0)

    def expression_name(self) -> str:
        """The palette name of the expression shown (``"smile"``, ``"au12"``)."""
        data = self.expression.currentData()
        return str(data) if data is not None else self.expression.currentText()

    def select_expression(self, name: str) -> None:
        """Show the palette expression ``name``."""
        index = self.expression.findData(name)
        if index >= 0:
            self.expression.setCurrentIndex(index)

    def _emit_expression(self) -> None:
        self.expression_changed.emit(self.expression_name(), self.weight())

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

    def show_state(
        self,
        contraction: Mapping[str, float],
        jaw_deg: float,
        gaze: tuple[float, float] | None = None,
        lids: float | None = None,
    ) -> None:
        """Set the sliders to the animator's values without emitting signals."""
        self._quiet = True  # the value labels follow, the signals do not fire
        try:
            for code, slider in self.muscles.items():
                slider.setValue(round(100 * float(contraction.get(code, 0.0))))
            self.jaw.setValue(round(10 * min(max(jaw_deg, 0.0), JAW_MAX_DEG)))
            if gaze is not None:
                self.gaze_yaw.setValue(round(gaze[0]))
                self.gaze_pitch.setValue(round(gaze[1]))
            if lids is not None:
                self.lids.setValue(round(100 * lids))
        finally:
            self._quiet = False

    def show_timeline(
        self,
        n_frames: int,
        frame: int,
        fps: float,
        *,
        playing: bool | None = None,
        computing_to: int | None = None,
    ) -> None:
        """The timeline at ``frame`` of ``n_frames`` (0: no track), without emitting signals.

        ``computing_to``: the frame being simulated toward (scrubbed past what was computed).
        """
        self._quiet = True
        try:
            has = n_frames > 0
            self.frame.setEnabled(has)
            self.play.setEnabled(has)
            self.save_track.setEnabled(has)
            self.frame.setRange(0, max(n_frames - 1, 0))
            if not self.frame.isSliderDown():
                self.frame.setValue(max(frame, 0))
            if playing is not None and self.play.isChecked() != playing:
                self.play.setChecked(playing)
            if has:
                end = (n_frames - 1) / fps
                text = f"{max(frame, 0) / fps:.2f} s / {end:.2f} s  (frame {max(frame, 0)} of {n_frames - 1})"
                if computing_to is not None:
                    text += f": simulating to frame {computing_to} …"
                self.time_label.setText(text)
            else:
                self.time_label.setText("0.00 s")
        finally:
            self._quiet = False

    def show_length(self, seconds: float) -> None:
        """The track's duration in the Length box (no signal)."""
        self._quiet = True
        try:
            self.length.setValue(seconds)
        finally:
            self._quiet = False

    def show_track(self, text: str) -> None:
        """What track is loaded (name, fps, keys, phonemes)."""
        self.track_label.setText(text)

    def show_track_message(self, text: str) -> None:
        """A problem with the track (a file that cannot be read); empty hides it."""
        self.track_message.setText(text)
        self.track_message.setVisible(bool(text))

    def show_status(self, text: str) -> None:
        self.status.setText(text)


def _slider(
    maximum: int, value: int, *, unit: str = " %", scale: float = 1.0, minimum: int = 0
) -> tuple[QSlider, QLabel]:
    slider = QSlider(Qt.Orientation.Horizontal)
    slider.setRange(minimum, maximum)
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
