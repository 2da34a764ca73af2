"""Undoable commands over the Case and the one command stack."""

from __future__ import annotations

from workbench.commands.stack import Command, CommandError, CommandStack, MacroCommand

__all__ = ["Command", "CommandError", "CommandStack", "MacroCommand"]
