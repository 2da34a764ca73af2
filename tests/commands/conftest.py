"""Fixtures shared by the command tests: an empty case and its stack."""

from __future__ import annotations

import pytest

from workbench.commands.stack import CommandStack
from workbench.model.case import Case


@pytest.fixture
def case() -> Case:
    return Case()


@pytest.fixture
def stack(case: Case) -> CommandStack:
    return CommandStack(case)
