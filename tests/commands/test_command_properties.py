"""Generic properties of every command type.

For every concrete command: ``do; undo`` restores ``case.to_state()`` exactly
and ``do; undo; redo`` equals ``do``.  A hypothesis state machine then runs
random sequences of pushes, undos, redos, gestures and failing commands
against a reference list of states.
"""

from __future__ import annotations

import json
from collections.abc import Callable

import numpy as np
import pytest
from hypothesis import settings
from hypothesis import strategies as st
from hypothesis.stateful import RuleBasedStateMachine, invariant, precondition, rule

from workbench.commands import appearance, case_edits, landmarks, reconstruction_setup, stack
from workbench.commands.appearance import SetAppearance
from workbench.commands.case_edits import (
    AddEvidence,
    DeleteParameter,
    ReplacePartCommand,
    SetCaseDetails,
    SetExaminer,
    SetNotes,
    SetParameter,
    SetSpecimen,
)
from workbench.commands.landmarks import (
    DeleteLandmark,
    LandmarkCommand,
    MoveLandmark,
    PlaceLandmark,
    ReplaceLandmarkSet,
    SetLandmarkStatus,
)
from workbench.commands.reconstruction_setup import (
    SetDepthOverride,
    SetDowelExclusion,
    SetDowelSettings,
    SetGuides,
    SetOrientation,
)
from workbench.commands.stack import Command, CommandStack, MacroCommand
from workbench.core.errors import WorkbenchError
from workbench.core.landmarks import Landmark, LandmarkSet
from workbench.core.mesh import Mesh
from workbench.model.appearance import Appearance, Hsv
from workbench.model.case import Case
from workbench.model.evidence import EvidenceFile
from workbench.model.meta import CaseMeta
from workbench.model.reconstruction_setup import DowelSettings, GuideList, Orientation
from workbench.model.specimen import Specimen
from workbench.model.state import states_equal

SHA_A, SHA_B = "a" * 64, "b" * 64


def tetra(scale: float = 1.0) -> Mesh:
    v = np.array([[0, 0, 0], [10, 0, 0], [0, 10, 0], [0, 0, 10]], float) * scale
    return Mesh(v, [[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]])


def base_case() -> Case:
    skull = LandmarkSet(
        "skull",
        (
            Landmark("n", [0.0, 50.0, 80.0]),
            Landmark("zy_l", [60.0, 20.0, 40.0], "suggested", 0.5),
            Landmark("pg", [np.nan] * 3, "absent"),
        ),
    )
    return Case(
        meta=CaseMeta.new("E. Xaminer"),
        evidence=(EvidenceFile("skull.obj", SHA_A, 10, "skull_mesh"),),
        specimen=Specimen(tetra(), "mm", None),
        landmarks={"skull": skull, "skin": LandmarkSet.from_points("skin", {"prn": (0, 1, 2)})},
        dowels=DowelSettings(overrides={"g": 5.0}, excluded=("zy_l",)),
        orientation=Orientation((0, 0, 1), (0, 1, 0)),
        guides=GuideList(({"id": "nose_tip", "value": [-20.0, 95.0]},)),
        parameters={"depth_table": "t0", "build": "average"},
        appearance=Appearance(tone="dark"),
    )


def shifted() -> np.ndarray:
    m = np.eye(4)
    m[:3, 3] = [1.0, 2.0, 3.0]
    return m


FACTORIES: dict[str, Callable[[], Command]] = {
    "place new": lambda: PlaceLandmark("skull", "g", [1, 2, 3]),
    "place over existing": lambda: PlaceLandmark("skull", "n", [1, 2, 3]),
    "place over absent": lambda: PlaceLandmark("skull", "pg", [1, 2, 3]),
    "move": lambda: MoveLandmark("skull", "n", [0, 51, 80]),
    "move suggested": lambda: MoveLandmark("skull", "zy_l", [61, 20, 40]),
    "status absent": lambda: SetLandmarkStatus("skull", "n", "absent"),
    "status missing new": lambda: SetLandmarkStatus("skin", "sn", "missing"),
    "confirm suggested": lambda: SetLandmarkStatus("skull", "zy_l", "placed"),
    "delete": lambda: DeleteLandmark("skull", "pg"),
    "replace set": lambda: ReplaceLandmarkSet(
        "skin", LandmarkSet.from_points("skin", {"sn": (1, 1, 1)}, "suggested"), "Suggest skin"
    ),
    "set parameter": lambda: SetParameter("build", "slim"),
    "set new parameter": lambda: SetParameter("guides", {"nose": [1.0, 2.0]}),
    "delete parameter": lambda: DeleteParameter("build"),
    "set specimen": lambda: SetSpecimen(tetra(2.0), "mm", shifted()),
    "set transform": lambda: SetSpecimen(tetra(), "mm", shifted()),
    "clear specimen": lambda: SetSpecimen(None),
    "set examiner": lambda: SetExaminer("Someone Else"),
    "set notes": lambda: SetNotes("skull received 2024-05-01"),
    "set case details": lambda: SetCaseDetails("Someone Else", "received sealed"),
    "add evidence": lambda: AddEvidence(EvidenceFile("ct.nrrd", SHA_B, 99, "ct_volume")),
    "set dowel table": lambda: SetDowelSettings(table="rhine_1983_sw_native_american"),
    "set dowel sex and build": lambda: SetDowelSettings(sex="female", build=-1.0),
    "set tissue model": lambda: SetDowelSettings(
        tissue_model="reference", region_factors={"nose": 1.3}
    ),
    "set depth override": lambda: SetDepthOverride("n", 6.5),
    "change depth override": lambda: SetDepthOverride("g", 7.0),
    "clear depth override": lambda: SetDepthOverride("g", None),
    "exclude dowel": lambda: SetDowelExclusion("n", True),
    "use dowel": lambda: SetDowelExclusion("zy_l", False),
    "set orientation": lambda: SetOrientation(Orientation((0, -1, 0), (0, 0, -1), (1, 0, 0))),
    "automatic orientation": lambda: SetOrientation(None),
    "set guides": lambda: SetGuides([{"id": "lip_parting", "kind": "hline", "value": [-70.0]}]),
    "recompute guides": lambda: SetGuides(None),
    "colour the face": lambda: SetAppearance(
        Appearance(tone="mst3", regions={"lips": (0.0, 0.5, 0.5)}, iris="green")
    ),
    "colour a region": lambda: SetAppearance(
        Appearance().with_colour("brows", Hsv(0.1, 0.3, 0.2)), merge_key="brows"
    ),
    "remove the face colours": lambda: SetAppearance(None),
    "macro": lambda: MacroCommand(
        commands=[
            PlaceLandmark("skull", "g", [1, 2, 3]),
            MoveLandmark("skull", "g", [4, 5, 6]),
            SetParameter("build", "obese"),
        ],
        label="Macro",
    ),
}

ABSTRACT = {Command, LandmarkCommand, ReplacePartCommand}


def concrete_command_types() -> set[type]:
    found = set()
    for module in (stack, landmarks, case_edits, reconstruction_setup, appearance):
        for obj in vars(module).values():
            if (
                isinstance(obj, type)
                and issubclass(obj, Command)
                and obj not in ABSTRACT
                and obj.__module__ == module.__name__
                and not obj.__name__.startswith("_")
            ):
                found.add(obj)
    return found


def test_every_command_type_is_covered() -> None:
    covered = {type(make()) for make in FACTORIES.values()}
    assert concrete_command_types() <= covered, concrete_command_types() - covered


@pytest.mark.parametrize("name", list(FACTORIES))
def test_do_undo_restores_and_redo_equals_do(name: str) -> None:
    case = base_case()
    before = case.to_state()
    command = FACTORIES[name]()
    command.do(case)
    after = case.to_state()
    assert not states_equal(before, after), "the command should change the case"
    command.undo(case)
    assert states_equal(case.to_state(), before)
    command.redo(case)
    assert states_equal(case.to_state(), after)
    command.undo(case)
    assert states_equal(case.to_state(), before)


@pytest.mark.parametrize("name", list(FACTORIES))
def test_through_the_stack_with_audit(name: str) -> None:
    case = base_case()
    before = case.to_state()
    s = CommandStack(case)
    command = FACTORIES[name]()
    s.push(command)
    after = case.to_state()
    s.undo()
    assert states_equal(case.to_state(), before)
    s.redo()
    assert states_equal(case.to_state(), after)
    assert s.undo_text == command.label != ""
    assert [r["action"] for r in case.audit.records] == ["do", "undo", "redo"]
    json.dumps(case.audit.records, allow_nan=False)


# ---------------------------------------------------------------- random sequences
CODES = st.sampled_from(["n", "g", "pg", "zy_l"])
SURFACES = st.sampled_from(["skull", "skin"])
POSITIONS = st.tuples(*[st.floats(-100, 100, allow_nan=False)] * 3)
STATUSES = st.sampled_from(["placed", "suggested", "absent", "missing"])

command_strategy = st.one_of(
    st.builds(PlaceLandmark, SURFACES, CODES, POSITIONS),
    st.builds(MoveLandmark, SURFACES, CODES, POSITIONS),
    st.builds(SetLandmarkStatus, SURFACES, CODES, STATUSES),
    st.builds(DeleteLandmark, SURFACES, CODES),
    st.builds(
        lambda pts: ReplaceLandmarkSet("skin", LandmarkSet.from_points("skin", pts)),
        st.dictionaries(CODES, POSITIONS, max_size=3),
    ),
    st.builds(
        SetParameter,
        st.sampled_from(["build", "depth_table", "x"]),
        st.one_of(st.integers(-5, 5), st.text(max_size=3), st.lists(st.booleans())),
    ),
    st.builds(DeleteParameter, st.sampled_from(["build", "x"])),
    st.builds(lambda b: SetDowelSettings(build=b), st.sampled_from(["normal", "obese", 1.0, -2])),
    st.builds(lambda sex: SetDowelSettings(sex=sex), st.sampled_from(["female", "male"])),
    st.builds(SetDepthOverride, CODES, st.one_of(st.none(), st.floats(0.5, 30))),
    st.builds(SetDowelExclusion, CODES, st.booleans()),
    st.builds(
        lambda o: SetOrientation(o),
        st.sampled_from([None, ((0, 0, 1), (0, 1, 0)), ((0, -1, 0), (0, 0, -1))]),
    ),
    st.builds(
        lambda ids: SetGuides(None if ids is None else [{"id": i, "value": [1.0]} for i in ids]),
        st.one_of(st.none(), st.lists(st.sampled_from(["a", "b"]), unique=True)),
    ),
    st.builds(lambda s: SetSpecimen(tetra(s)), st.sampled_from([0.5, 1.0, 2.0])),
    st.builds(SetExaminer, st.text(max_size=5)),
    st.builds(
        lambda v, key: SetAppearance(
            None if v is None else Appearance().with_colour("lips", Hsv(0.0, 0.5, v)),
            merge_key=key,
        ),
        st.sampled_from([None, 0.2, 0.4]),
        st.sampled_from(["", "lips"]),
    ),
    st.builds(
        lambda n, sha: AddEvidence(EvidenceFile(n, sha, 10, "other")),
        st.sampled_from(["a.bin", "b.bin"]),
        st.sampled_from([SHA_A, SHA_B]),
    ),
)


class StackMachine(RuleBasedStateMachine):
    """Stack vs. a reference list of states (one per undo step)."""

    def __init__(self) -> None:
        super().__init__()
        self.case = base_case()
        self.stack = CommandStack(self.case)
        self.states = [self.case.to_state()]
        self.redo_states: list[dict] = []
        self.gesture_start: dict | None = None

    @rule(command=command_strategy)
    def push(self, command: Command) -> None:
        before, size = self.case.to_state(), len(self.stack)
        try:
            self.stack.push(command)
        except WorkbenchError:
            assert states_equal(self.case.to_state(), before)
            assert len(self.stack) == size
            return
        if self.gesture_start is None:
            if len(self.stack) == size:  # merged into the last step
                self.states[-1] = self.case.to_state()
            else:
                self.states.append(self.case.to_state())
            self.redo_states.clear()

    @rule(code=st.just("n"), position=POSITIONS)
    def drag(self, code: str, position: tuple[float, float, float]) -> None:
        """Moves of the same landmark, so merging happens often."""
        self.push(MoveLandmark("skull", code, position))

    @rule(value=st.integers(0, 3))
    def slide(self, value: int) -> None:
        self.push(SetParameter("build", value))

    @precondition(lambda self: self.gesture_start is None)
    @rule()
    def undo(self) -> None:
        if self.stack.can_undo:
            self.stack.undo()
            self.redo_states.append(self.states.pop())

    @precondition(lambda self: self.gesture_start is None)
    @rule()
    def redo(self) -> None:
        if self.stack.can_redo:
            self.stack.redo()
            self.states.append(self.redo_states.pop())

    @precondition(lambda self: self.gesture_start is None)
    @rule()
    def undo_redo(self) -> None:
        if self.stack.can_undo:
            self.undo()
            self.matches_reference()
            self.redo()

    @precondition(lambda self: self.gesture_start is None)
    @rule()
    def begin(self) -> None:
        self.stack.begin_gesture("drag")
        self.gesture_start = self.case.to_state()

    @precondition(lambda self: self.gesture_start is not None)
    @rule()
    def commit(self) -> None:
        size = len(self.stack)
        self.stack.commit_gesture()
        if len(self.stack) > size:
            self.states.append(self.case.to_state())
            self.redo_states.clear()
        self.gesture_start = None

    @precondition(lambda self: self.gesture_start is not None)
    @rule()
    def abort(self) -> None:
        self.stack.abort_gesture()
        assert states_equal(self.case.to_state(), self.gesture_start)
        self.gesture_start = None

    @invariant()
    def matches_reference(self) -> None:
        assert len(self.stack) == len(self.states) - 1
        if self.gesture_start is None:
            assert states_equal(self.case.to_state(), self.states[-1])

    def teardown(self) -> None:
        if self.gesture_start is not None:
            self.stack.abort_gesture()
        while self.stack.can_undo:
            self.stack.undo()
        assert states_equal(self.case.to_state(), self.states[0])


StackMachine.TestCase.settings = settings(max_examples=150, stateful_step_count=30, deadline=None)
test_random_command_sequences = StackMachine.TestCase
