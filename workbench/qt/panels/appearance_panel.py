"""Appearance dock: the colours of the fitted face (skin tone, regions, iris).

Widgets and signals only; :class:`workbench.qt.tools.appearance.AppearanceTool`
turns them into :class:`~workbench.commands.appearance.SetAppearance` commands,
colours the face layer and hands the colours back through
:meth:`AppearancePanel.show_colours`.

The dock shows, top to bottom: the note that the colours are an artistic
choice and not evidence; "Colour the face" (show the colours on the face
layer, a view setting); the skin-tone preset and the iris colour; the hair,
brows, beard and moustache styles of the library (:mod:`workbench.core.grooming`),
under their own note that they are artistic additions, not evidence; one box per
region (skin, cheeks, around the eyes, brows, lips, hair and beard) with a
swatch, hue (0-359°), saturation and value (0-100 %) sliders and "Follow the
skin" (drop the colour set by hand: the region follows the base by its rule
again; the skin's and the hair's boxes have "Use the preset"); and "Remove
colours" (the case keeps no colouring).
"""

from __future__ import annotations

from collections.abc import Mapping

from PySide6.QtCore import Qt, Signal
from PySide6.QtGui import QColor, QIcon, QPixmap
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

from workbench.core.appearance import IRIS_COLOURS, MONK_SCALE, SKIN_TONES
from workbench.core.grooming import ARTISTIC_NOTE as GROOMING_NOTE
from workbench.core.grooming import KINDS, LIBRARY, NONE
from workbench.model.appearance import ARTISTIC_NOTE, REGION_TITLES, REGIONS, Appearance, Hsv

#: what the dock calls each kind of hair
KIND_TITLES = {"hair": "Hair", "brows": "Brows", "beard": "Beard", "moustache": "Moustache"}
#: regions whose "follow" button goes back to a preset rather than to the skin
PRESET_REGIONS = ("skin", "hair")

#: slider ranges: hue in degrees, saturation and value in percent
SCALES = {"h": 360, "s": 100, "v": 100}
CHANNEL_TITLES = {"h": "Hue", "s": "Saturation", "v": "Value"}
#: the presets in the order the combo lists them: the three names, then the Monk scale
TONE_ORDER = ("light", "medium", "dark", *(f"mst{k}" for k in range(1, len(MONK_SCALE) + 1)))


def tone_title(name: str) -> str:
    """What the combo calls preset ``name`` ("medium (MST 6)", "MST 2")."""
    if name.startswith("mst"):
        return f"MST {name[3:]}"
    same = next(
        (k for k in SKIN_TONES if k.startswith("mst") and SKIN_TONES[k] == SKIN_TONES[name]), ""
    )
    return f"{name} (MST {same[3:]})" if same else name


def _swatch(rgb: tuple[int, int, int], size: int = 16) -> QPixmap:
    pixmap = QPixmap(size, size)
    pixmap.fill(QColor(*rgb))
    return pixmap


class RegionBox(QGroupBox):
    """One region's colour: a swatch, H/S/V sliders and "Follow the skin"."""

    def __init__(self, region: str, parent: QWidget | None = None) -> None:
        super().__init__(REGION_TITLES[region], parent)
        self.region = region
        grid = QGridLayout(self)
        grid.setContentsMargins(6, 4, 6, 4)
        self.swatch = QLabel()
        self.swatch.setFixedSize(28, 28)
        self.swatch.setToolTip("The colour this region is painted with")
        grid.addWidget(self.swatch, 0, 0, 3, 1)
        self.sliders: dict[str, QSlider] = {}
        self.values: dict[str, QLabel] = {}
        for row, key in enumerate("hsv"):
            slider = QSlider(Qt.Orientation.Horizontal)
            slider.setRange(0, SCALES[key] - 1 if key == "h" else SCALES[key])
            slider.setObjectName(f"{region}_{key}")
            slider.setToolTip(f"{CHANNEL_TITLES[key]} of the {REGION_TITLES[region].lower()}")
            value = QLabel()
            value.setMinimumWidth(36)
            grid.addWidget(QLabel(CHANNEL_TITLES[key]), row, 1)
            grid.addWidget(slider, row, 2)
            grid.addWidget(value, row, 3)
            self.sliders[key], self.values[key] = slider, value
        self.follow = QPushButton(
            "Use the preset" if region in PRESET_REGIONS else "Follow the skin"
        )
        self.follow.setToolTip(
            "Drop the colour set by hand: the region follows the skin tone by its rule"
            if region not in PRESET_REGIONS
            else (
                "Drop the base set by hand: the skin takes the preset chosen above"
                if region == "skin"
                else "Drop the colour set by hand: the hair takes its preset (dark brown)"
            )
        )
        grid.addWidget(self.follow, 3, 1, 1, 3)
        grid.setColumnStretch(2, 1)

    def hsv(self) -> Hsv:
        """The sliders' colour."""
        s = self.sliders
        return Hsv(
            s["h"].value() / SCALES["h"], s["s"].value() / SCALES["s"], s["v"].value() / SCALES["v"]
        )

    def set_colour(self, colour: Hsv, rgb: tuple[int, int, int], own: bool) -> None:
        """Set the sliders (signals blocked), the swatch and whether the colour is set by hand."""
        blocked = [s.blockSignals(True) for s in self.sliders.values()]
        try:
            for key, x in zip("hsv", colour.to_state(), strict=True):
                value = round(x * SCALES[key])
                self.sliders[key].setValue(value % 360 if key == "h" else value)
        finally:
            for s, b in zip(self.sliders.values(), blocked, strict=True):
                s.blockSignals(b)
        self.show_values()
        self.swatch.setPixmap(_swatch(rgb, 28))
        self.follow.setEnabled(own)
        self.setTitle(REGION_TITLES[self.region] + (" (set by hand)" if own else ""))

    def show_values(self) -> None:
        for key, slider in self.sliders.items():
            self.values[key].setText(f"{slider.value()}{'°' if key == 'h' else ' %'}")


class AppearancePanel(QWidget):
    """The Appearance dock (see the module docstring).

    Signals
    -------
    shown_toggled(bool)
        "Colour the face" switched.
    tone_chosen(str)
        A skin-tone preset picked (its key in ``SKIN_TONES``).
    iris_chosen(str)
        An iris colour picked.
    colour_changed(str, object, bool)
        A region's sliders moved: region, :class:`~workbench.model.appearance.Hsv`,
        and whether the move is finished (False while a slider is dragged).
    follow_requested(str)
        "Follow the skin" (or "Use the preset") of a region.
    remove_requested()
        "Remove colours".
    style_chosen(str, str)
        A hair, brows, beard or moustache style picked: kind and style (``"none"``).
    """

    shown_toggled = Signal(bool)
    tone_chosen = Signal(str)
    iris_chosen = Signal(str)
    colour_changed = Signal(str, object, bool)
    follow_requested = Signal(str)
    remove_requested = Signal()
    style_chosen = Signal(str, str)

    def __init__(self, parent: QWidget | None = None) -> None:
        super().__init__(parent)
        layout = QVBoxLayout(self)
        self.note = QLabel(f"<i>{ARTISTIC_NOTE}</i>")
        self.note.setWordWrap(True)
        self.note.setObjectName("appearance_note")
        layout.addWidget(self.note)
        self.shown = QCheckBox("Colour the face")
        self.shown.setToolTip("Show these colours on the face layer (a view setting)")
        self.shown.toggled.connect(self.shown_toggled)
        layout.addWidget(self.shown)
        layout.addLayout(self._build_presets())
        layout.addWidget(self._build_styles())
        self.boxes: dict[str, RegionBox] = {}
        for region in REGIONS:
            box = RegionBox(region)
            for slider in box.sliders.values():
                slider.valueChanged.connect(lambda _v, b=box: self._moved(b, final=False))
                slider.sliderReleased.connect(lambda b=box: self._moved(b, final=True))
            box.follow.clicked.connect(lambda _c=False, r=region: self.follow_requested.emit(r))
            layout.addWidget(box)
            self.boxes[region] = box
        row = QHBoxLayout()
        self.remove = QPushButton("Remove colours")
        self.remove.setToolTip("The case keeps no colouring (the face is drawn plain)")
        self.remove.clicked.connect(self.remove_requested)
        row.addWidget(self.remove)
        row.addStretch(1)
        layout.addLayout(row)
        self.status = QLabel("")
        self.status.setWordWrap(True)
        layout.addWidget(self.status)
        layout.addStretch(1)

    def _build_presets(self) -> QFormLayout:
        form = QFormLayout()
        self.tone = QComboBox()
        self.tone.setObjectName("appearance_tone")
        for name in TONE_ORDER:
            self.tone.addItem(QIcon(_swatch(SKIN_TONES[name].srgb)), tone_title(name), name)
            self.tone.setItemData(
                self.tone.count() - 1, SKIN_TONES[name].source, Qt.ItemDataRole.ToolTipRole
            )
        self.tone.activated.connect(lambda i: self.tone_chosen.emit(self.tone.itemData(i)))
        form.addRow("Skin tone", self.tone)
        self.base_note = QLabel("")
        self.base_note.setWordWrap(True)
        form.addRow("", self.base_note)
        self.iris = QComboBox()
        self.iris.setObjectName("appearance_iris")
        for name, (_inner, outer) in IRIS_COLOURS.items():
            self.iris.addItem(QIcon(_swatch(outer.srgb)), name, name)
            self.iris.setItemData(self.iris.count() - 1, outer.source, Qt.ItemDataRole.ToolTipRole)
        self.iris.setToolTip("The eyes' colour in exported heads (the face layer shows the skin)")
        self.iris.activated.connect(lambda i: self.iris_chosen.emit(self.iris.itemData(i)))
        form.addRow("Iris", self.iris)
        return form

    def _build_styles(self) -> QGroupBox:
        group = QGroupBox("Hair and brows (artistic additions)")
        form = QFormLayout(group)
        note = QLabel(f"<i>{GROOMING_NOTE}</i>")
        note.setWordWrap(True)
        note.setObjectName("grooming_note")
        form.addRow(note)
        self.styles: dict[str, QComboBox] = {}
        for kind in KINDS:
            combo = QComboBox()
            combo.setObjectName(f"style_{kind}")
            combo.addItem("none", NONE)
            for name, style in LIBRARY[kind].items():
                combo.addItem(style.title, name)
            combo.setToolTip(
                f"{KIND_TITLES[kind]} grown on the face from its landmarks; follows builds, "
                "age and expressions"
            )
            combo.activated.connect(
                lambda i, k=kind, c=combo: self.style_chosen.emit(k, c.itemData(i))
            )
            form.addRow(KIND_TITLES[kind], combo)
            self.styles[kind] = combo
        return group

    def _moved(self, box: RegionBox, *, final: bool) -> None:
        box.show_values()
        dragging = any(s.isSliderDown() for s in box.sliders.values())
        self.colour_changed.emit(box.region, box.hsv(), final or not dragging)

    # ------------------------------------------------------------ shown by the tool
    def show_colours(
        self,
        appearance: Appearance | None,
        colours: Mapping[str, Hsv],
        rgb: Mapping[str, tuple[int, int, int]],
    ) -> None:
        """Set every widget (signals blocked) to ``appearance`` (None: the defaults) with
        ``colours`` / ``rgb`` the colour each region is painted with."""
        look = appearance if appearance is not None else Appearance()
        pairs = [(self.tone, look.tone), (self.iris, look.iris)]
        pairs += [(self.styles[k], look.style(k)) for k in KINDS]
        for combo, key in pairs:
            blocked = combo.blockSignals(True)
            combo.setCurrentIndex(max(0, combo.findData(key)))
            combo.blockSignals(blocked)
        for region, box in self.boxes.items():
            box.set_colour(colours[region], rgb[region], look.colour(region) is not None)
        self.base_note.setText(
            "The base is set by hand (Skin sliders); pick a preset to go back to one."
            if look.custom_base
            else SKIN_TONES[look.tone].source
        )
        self.remove.setEnabled(appearance is not None)

    def set_shown(self, on: bool) -> None:
        """Tick "Colour the face" without emitting :attr:`shown_toggled`."""
        blocked = self.shown.blockSignals(True)
        self.shown.setChecked(on)
        self.shown.blockSignals(blocked)

    def show_status(self, text: str) -> None:
        self.status.setText(text)
