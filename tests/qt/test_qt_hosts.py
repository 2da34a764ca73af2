"""The host protocols name what their users call, and the window and tools provide it.

``mypy`` checks the same at the call sites; this catches a menu action whose
method is missing from :class:`~workbench.qt.hosts.MenuHost` (the menus call
methods by name, which ``mypy`` cannot follow).
"""

from __future__ import annotations

import pytest

pytest.importorskip("pytestqt")


def _members(protocol: type) -> set[str]:
    names = {n for n in vars(protocol) if not n.startswith("_")}
    return names | set(getattr(protocol, "__annotations__", {}))


def test_every_menu_action_is_in_the_menu_host() -> None:
    from workbench.qt.actions import ACTIONS
    from workbench.qt.hosts import MenuHost

    missing = [spec.method for spec in ACTIONS if spec.method not in _members(MenuHost)]
    assert not missing


def test_window_and_tools_provide_their_hosts() -> None:
    from workbench.qt import hosts
    from workbench.qt.main_window import MainWindow
    from workbench.qt.tools.drags import DragTool

    window_attrs = {
        "document",
        "messages",
        "interactive",
        "autosaver",
        "runner",
        "scene",
        "docks",
    }  # set in MainWindow.__init__
    for protocol in (
        hosts.AutosaveHost,
        hosts.CtImportHost,
        hosts.MenuHost,
        hosts.Feedback,
        hosts.FileHost,
    ):
        missing = {
            n for n in _members(protocol) if not hasattr(MainWindow, n) and n not in window_attrs
        }
        assert not missing, (protocol.__name__, missing)
    assert _members(hosts.GuideDragHost) <= set(vars(DragTool))
