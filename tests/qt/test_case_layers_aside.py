"""The case's layers set aside by tools with heads of their own (issue 33, issue 34): shared
per view, so two tools switching places in either order never show the case's face under
the next tool's head."""

from __future__ import annotations

from workbench.qt.tools.common import CaseLayersAside


class _Scene:
    def __init__(self) -> None:
        self.visible = {"skull": True, "face": True, "hair": True, "muscles": False}

    def has(self, layer: str) -> bool:
        return layer != "muscles"

    def set_visible(self, layer: str, on: bool) -> None:
        self.visible[layer] = on


def test_the_last_tool_to_leave_brings_the_layers_back() -> None:
    scene = _Scene()
    age, animate = CaseLayersAside(scene), CaseLayersAside(scene)
    age.set_aside(True)
    assert not any(scene.visible.values())
    animate.set_aside(True)  # the next tab reports first ...
    age.set_aside(False)  # ... then the one left: the face must stay hidden
    assert not scene.visible["face"] and not scene.visible["hair"]
    animate.set_aside(False)
    assert scene.visible == {"skull": True, "face": True, "hair": True, "muscles": False}
    # a tool leaving that was never in front changes nothing
    age.set_aside(False)
    assert scene.visible["face"]


def test_a_layer_the_user_showed_meanwhile_is_left_alone() -> None:
    scene = _Scene()
    tool = CaseLayersAside(scene)
    tool.set_aside(True)
    scene.visible["skull"] = True  # the user showed the skull while the tool was in front
    tool.set_aside(False)
    assert scene.visible["skull"] and scene.visible["face"] and not scene.visible["muscles"]
