"""Undoable commands over the Case and the one command stack."""
