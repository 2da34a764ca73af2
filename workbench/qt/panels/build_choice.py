"""The build control of the Dowels and Scan fit docks, in words an artist reads.

The named builds come from the build model (``data_tables/build/``: slender,
average and heavy at stated BMI values; regional effects, not a uniform
shift) and work with every depth table that gives SDs; the "k SD" choices keep
the old uniform mean + k SD of the table group, for comparison.  Each item
shows its meaning and carries the value the case stores (``normal`` for the
average, as before; ``slender``, ``heavy``; a number k).
"""

from __future__ import annotations

from PySide6.QtWidgets import QComboBox, QWidget

from workbench.io.build_model import load_build_model

#: the uniform choices: mean + k SD of the table group at every landmark
SD_CHOICES = ((-2.0, "thin everywhere"), (-1.0, ""), (1.0, ""), (2.0, "full everywhere"))

TOOLTIP = (
    "How heavy the person was.  slender, average and heavy: the build model's faces at "
    "the BMI shown (cheeks, jaw and chin change most, forehead and nose least; "
    "data_tables/build).  ±k SD: every depth of the table moved by k standard deviations "
    "of its group, the same everywhere (for comparison).  The report shows all three "
    "faces and the 95 % band whichever is chosen here."
)


def build_choices() -> list[tuple[str, str]]:
    """``(label, value)`` of every build offered, the default (average) first."""
    model = load_build_model()
    named = [
        (f"average (BMI {model.bmi('average'):g}, build unknown)", "normal"),
        (f"slender (BMI {model.bmi('slender'):g})", "slender"),
        (f"heavy (BMI {model.bmi('heavy'):g})", "heavy"),
    ]
    uniform = [
        (f"{k:+g} SD of the table{', ' + why if why else ''}", f"{k:g}") for k, why in SD_CHOICES
    ]
    return named + uniform


def build_combo(parent: QWidget | None = None) -> QComboBox:
    """A combo box of :func:`build_choices` (labels shown, values as item data)."""
    combo = QComboBox(parent)
    for label, value in build_choices():
        combo.addItem(label, value)
    combo.setToolTip(TOOLTIP)
    return combo


def select_build(combo: QComboBox, value: str) -> None:
    """Show ``value`` (a stored build: ``normal``, ``heavy``, ``-1``, ``bmi:27``, an alias);
    a value not offered is added as it is."""
    # the list offers the average as "normal" (what older cases store) and "heavy" for "obese"
    wanted = {"average": "normal", "obese": "heavy"}.get(value, value)
    index = combo.findData(wanted)
    if index < 0:
        combo.addItem(value, value)
        index = combo.count() - 1
    combo.setCurrentIndex(index)


def chosen_build(combo: QComboBox) -> str:
    """The value of the build shown."""
    data = combo.currentData()
    return str(data) if data is not None else combo.currentText()
