"""Window tests: a private autosave folder; windows are closed, never deleted mid-session.

Closed windows are kept (strong references) until the session ends instead of
being deleted with ``deleteLater`` by pytest-qt: deleting a whole window tree
while the next test's workers and views run crashed intermittently inside
shiboken (``BindingManager::unregisterWrapper`` in ``QWidget::~QWidget``,
about one run in three under Xvfb).  Every window's 3D views are still
finalized in its teardown (``plotter.close()``), so no GL resources are held.
"""

from __future__ import annotations

import gc

import pytest
from pytestqt.qtbot import QtBot

_KEPT: list = []


def _keep(self, widget, *, before_close_func=None) -> None:
    """``qtbot.addWidget``: closed at the end of the test, kept alive until the session ends."""
    request = self._request
    request.addfinalizer(
        lambda: (before_close_func(widget) if before_close_func else None, widget.close())
    )
    _KEPT.append(widget)


QtBot.addWidget = _keep  # type: ignore[method-assign]


@pytest.fixture(autouse=True)
def _private_autosave(monkeypatch, tmp_path_factory):
    monkeypatch.setenv("WORKBENCH_AUTOSAVE_DIR", str(tmp_path_factory.mktemp("autosave")))
    yield
    gc.collect()


@pytest.fixture
def new_window(qtbot):
    """A factory of shown, non-interactive main windows (``new_window(width, height)``).

    Each window's worker and 3D view are shut down in teardown (HEADLESS.md:
    finalize VTK while the GL context exists).
    """
    from workbench.qt.main_window import MainWindow

    made = []

    def make(width: int = 1200, height: int = 800):
        w = MainWindow(auto_update=False, interactive=False)
        qtbot.addWidget(w)
        w.resize(width, height)
        w.show()
        qtbot.waitExposed(w)
        made.append(w)
        return w

    yield make
    for w in made:
        w.runner.shutdown()
        w.plotter.close()
        w.close()


@pytest.fixture
def window(new_window):
    return new_window()
