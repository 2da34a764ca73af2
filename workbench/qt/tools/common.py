"""Small helpers more than one tool uses (no Qt widgets here)."""

from __future__ import annotations

import os
from pathlib import Path


def folder_is_free(folder: str | Path) -> bool:
    """True when ``folder`` does not exist or is an empty folder."""
    path = Path(folder)
    return not os.path.lexists(path) or (path.is_dir() and not any(path.iterdir()))
