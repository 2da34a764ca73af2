"""The window's session (derived results and their signals) and the closed-view helper."""

from __future__ import annotations

import pytest

pytest.importorskip("pytestqt")


def test_session_stores_and_signals(qtbot) -> None:
    from workbench.qt.session import Session

    session = Session()
    seen: list[tuple[str, object]] = []
    session.fit_changed.connect(lambda v: seen.append(("fit", v)))
    session.preview_changed.connect(lambda v: seen.append(("preview", v)))
    session.truth_changed.connect(lambda v: seen.append(("truth", v)))
    session.comparison_changed.connect(lambda v: seen.append(("comparison", v)))
    assert (session.fit, session.preview, session.truth, session.comparison) == (None,) * 4

    fit, preview, mesh, comparison = object(), object(), object(), object()
    session.set_fit(fit)  # any object stands in for a result
    session.set_preview(preview)
    session.set_truth("skin.ply", mesh)
    session.set_comparison(comparison)
    assert session.fit is fit and session.preview is preview
    assert session.truth == ("skin.ply", mesh) and session.comparison is comparison
    assert seen == [
        ("fit", fit),
        ("preview", preview),
        ("truth", ("skin.ply", mesh)),
        ("comparison", comparison),
    ]

    seen.clear()
    session.clear_fit()  # a new case: fit and dowels go, the true skin stays
    assert session.fit is None and session.preview is None and session.truth is not None
    assert seen == [("fit", None), ("preview", None)]
    session.clear_fit()  # told again, also when nothing changed
    assert seen[2:] == [("fit", None), ("preview", None)]


def test_is_closed_reads_the_view_flag() -> None:
    from workbench.qt.scene import is_closed

    class View:
        _closed = False

    view = View()
    assert not is_closed(view) and not is_closed(object())
    view._closed = True
    assert is_closed(view)
