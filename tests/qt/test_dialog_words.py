"""The window's dialogs speak of what they offer, not of command-line options (issue 33)."""

from __future__ import annotations

import pytest

pytest.importorskip("PySide6")


@pytest.mark.parametrize("extent", [19.0, 0.19, 4.0e-4])
def test_the_units_question_names_the_dialogs_choices_not_options(extent):
    from workbench.core.units import detect_units_from_extent
    from workbench.qt.dialogs import _in_window_words

    report = detect_units_from_extent(extent, "head")
    assert report.needs_confirmation and "--" in report.message  # the CLI's own advice
    text = _in_window_words(report.message)
    assert "--" not in text and "below" in text
