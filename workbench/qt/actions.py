"""Menus and keyboard shortcuts of the main window, declared as data.

One table (:data:`ACTIONS`) lists every action: id, menu, title, shortcut
and the window method it calls, so a test can check that each exists and
is wired.  View-menu layer toggles are generated from
:data:`workbench.qt.scene.LAYERS`; they set the scene's layer visibility and
follow it back (:attr:`~workbench.qt.scene.SceneView.layer_changed`), so they
agree with the Layers dock whichever one the user clicks.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

from PySide6.QtGui import QAction, QKeySequence

from workbench.qt.scene import LAYERS

if TYPE_CHECKING:
    from workbench.qt.hosts import MenuHost


@dataclass(frozen=True)
class ActionSpec:
    id: str
    menu: str
    title: str
    shortcut: str | QKeySequence.StandardKey | None
    method: str
    tip: str = ""


ACTIONS: tuple[ActionSpec, ...] = (
    ActionSpec(
        "open_skull",
        "&File",
        "Open skull &mesh…",
        "Ctrl+O",
        "ask_open_skull",
        "Start a case from a skull surface (PLY, STL, OBJ, VTK, VTP)",
    ),
    ActionSpec(
        "open_ct",
        "&File",
        "Open &CT…",
        "Ctrl+Shift+O",
        "ask_open_ct",
        "Extract the bone surface of a CT volume and start a case from it",
    ),
    ActionSpec(
        "open_case",
        "&File",
        "Open c&ase…",
        "Ctrl+Alt+O",
        "ask_open_case",
        "Open a saved .fcase file",
    ),
    ActionSpec(
        "save",
        "&File",
        "&Save",
        QKeySequence.StandardKey.Save,
        "save",
        "Save the case (atomic: a failed save leaves the old file)",
    ),
    ActionSpec("save_as", "&File", "Save &As…", QKeySequence.StandardKey.SaveAs, "ask_save_as"),
    ActionSpec(
        "case_details",
        "&File",
        "Case &details…",
        None,
        "ask_case_details",
        "The examiner's name (printed on the report) and the case notes; one undo step",
    ),
    ActionSpec(
        "export",
        "&File",
        "&Export…",
        "Ctrl+E",
        "ask_export",
        "Face and head meshes (PLY/OBJ/STL), landmarks (.mrk.json, .fcsv) and the PDF report",
    ),
    ActionSpec("quit", "&File", "&Quit", QKeySequence.StandardKey.Quit, "close"),
    ActionSpec("undo", "&Edit", "&Undo", QKeySequence.StandardKey.Undo, "undo"),
    ActionSpec("redo", "&Edit", "&Redo", QKeySequence.StandardKey.Redo, "redo"),
    ActionSpec("mark_absent", "&Edit", "Mark selected landmark &absent", "A", "mark_absent"),
    ActionSpec(
        "snap",
        "&Edit",
        "Sna&p selected landmark to its feature",
        "S",
        "snap_selected",
        "Move the selected skull landmark to the feature its definition names "
        "(e.g. the most anterior midline point for glabella), near where it is",
    ),
    ActionSpec(
        "next_missing", "&Edit", "Select &next missing landmark", "N", "select_next_missing"
    ),
    ActionSpec(
        "suggest", "&Tools", "&Suggest the rest of the landmarks", "Ctrl+L", "suggest_landmarks"
    ),
    ActionSpec("reconstruct", "&Tools", "&Reconstruct face", "Ctrl+R", "reconstruct"),
    ActionSpec("load_truth", "&Tools", "Compare with a &true skin…", "Ctrl+T", "ask_load_truth"),
    ActionSpec("reset_view", "&View", "Reset &camera", "R", "reset_view"),
    ActionSpec("screenshot", "&View", "Save &window picture…", "Ctrl+Shift+S", "ask_screenshot"),
    ActionSpec(
        "portrait",
        "&View",
        "&Portrait…",
        None,
        "show_portrait",
        "The fitted face as front, three-quarter and profile portraits (colour or clay); "
        "Save… writes them as PNG and TIFF at print size",
    ),
)


#: the Fit scan tool's entries (:class:`workbench.qt.tools.scan_fit.tool.ScanFitTool` methods),
#: added by :func:`add_tool_actions` after the window's own menus
SCAN_FIT_ACTIONS: tuple[ActionSpec, ...] = (
    ActionSpec(
        "open_scan",
        "&File",
        "Open face sca&n…",
        "Ctrl+Shift+N",
        "ask_open_scan",
        "Open a surface scan of a face to fit the reference head to it (Fit scan dock)",
    ),
    ActionSpec(
        "fit_scan",
        "&Tools",
        "&Fit scan",
        "Ctrl+Shift+F",
        "fit",
        "Fit the reference head to the open scan (from zero or 3+ placed skin landmarks)",
    ),
    ActionSpec(
        "save_scan_pack",
        "&Tools",
        "Save fitted scan &pack…",
        None,
        "ask_save",
        "Fit with the same inputs and write the template pack and fit_report.json",
    ),
)


#: the Animate tool's entries (window methods: the dock comes to the front first)
ANIMATE_ACTIONS: tuple[ActionSpec, ...] = (
    ActionSpec(
        "animate",
        "&Tools",
        "&Animate a reference head",
        "Ctrl+Shift+A",
        "show_animate",
        "Expression presets, muscle sliders and the jaw on a reference head (Animate dock; "
        "view only, the case is not changed)",
    ),
)


#: the Age progression tool's entries (window methods: the dock comes to the front first)
AGE_ACTIONS: tuple[ActionSpec, ...] = (
    ActionSpec(
        "age",
        "&Tools",
        "A&ge progression",
        "Ctrl+Shift+G",
        "show_age",
        "A head at another age from growth norms: target-age slider, before/after, "
        "z-score table, export (Age progression dock; the case is not changed)",
    ),
)


def add_tool_actions(
    window: MenuHost, tool: object, specs: tuple[ActionSpec, ...]
) -> dict[str, QAction]:
    """Add ``specs`` (methods of ``tool``) to the window's existing menus, after their
    entries of the same menu that open things (File) or at the end (other menus)."""
    bar = window.menuBar()
    menus = {a.text(): a.menu() for a in bar.actions() if a.menu() is not None}
    out: dict[str, QAction] = {}
    for spec in specs:
        menu: Any = menus.get(spec.menu)
        if menu is None:
            menu = menus[spec.menu] = bar.addMenu(spec.menu)
        action = QAction(spec.title, window.window())
        if spec.shortcut is not None:
            action.setShortcut(QKeySequence(spec.shortcut))
        if spec.tip:
            action.setStatusTip(spec.tip)
            action.setToolTip(spec.tip)
        action.triggered.connect(lambda _checked=False, m=spec.method: getattr(tool, m)())
        # File: after the "Open …" entries; elsewhere at the end
        opens = [a for a in menu.actions() if a.text().startswith("Open")]
        after = menu.actions().index(opens[-1]) + 1 if spec.menu == "&File" and opens else None
        rest = menu.actions()[after:] if after is not None else []
        if rest:
            menu.insertAction(rest[0], action)
        else:
            menu.addAction(action)
        out[spec.id] = action
    return out


def build_menus(window: MenuHost) -> dict[str, QAction]:
    """Create the menus of ``window``; returns ``{action id: QAction}``."""
    menus: dict[str, Any] = {}
    out: dict[str, QAction] = {}
    bar = window.menuBar()
    for spec in ACTIONS:
        if spec.menu not in menus:
            menus[spec.menu] = bar.addMenu(spec.menu)
        action = QAction(spec.title, window.window())
        if spec.shortcut is not None:
            action.setShortcut(QKeySequence(spec.shortcut))
        if spec.tip:
            action.setStatusTip(spec.tip)
            action.setToolTip(spec.tip)
        action.triggered.connect(lambda _checked=False, m=spec.method: getattr(window, m)())
        menus[spec.menu].addAction(action)
        out[spec.id] = action
        if spec.id in ("export", "redo"):
            menus[spec.menu].addSeparator()
    view = menus["&View"]
    second = QAction("Second &view: guides, frontal / lateral", window.window())
    second.setCheckable(True)
    second.setShortcut(QKeySequence("F2"))
    second.setStatusTip("The orthographic guide view beside the 3D view (drag the guides there)")
    second.toggled.connect(window.user_toggled_guide_view)
    view.addAction(second)
    out["guide_view"] = second
    for key, dock in window.docks.items():
        toggle = dock.toggleViewAction()
        view.addAction(toggle)
        out[f"dock_{key}"] = toggle
    view.addSeparator()
    scene = window.scene
    for layer, title in LAYERS.items():
        action = QAction(title, window.window())
        action.setCheckable(True)
        action.setChecked(scene.visible[layer])
        action.setStatusTip(f"Show or hide the {title.lower()} layer (opacity: Layers dock)")
        action.toggled.connect(lambda on, name=layer: scene.set_visible(name, on))
        view.addAction(action)
        out[f"layer_{layer}"] = action
    scene.layer_changed.connect(
        lambda name: _follow_layer(out.get(f"layer_{name}"), scene.visible.get(name, True))
    )
    return out


def _follow_layer(action: QAction | None, visible: bool) -> None:
    """Tick a View-menu layer toggle to match the scene, without re-emitting ``toggled``."""
    if action is None or action.isChecked() == visible:
        return
    blocked = action.blockSignals(True)
    try:
        action.setChecked(visible)
    finally:
        action.blockSignals(blocked)
