"""Where the shipped data tables are, found in one place.

An installed wheel carries them as ``workbench/_data/data_tables`` (copied by
``setup.py``); a source checkout has ``data_tables/`` beside the package.
Every reader of a shipped table (depth tables, landmark catalogue, guide
rules, muscles, template data, JSON schemas) starts from
:func:`data_tables_dir`.
"""

from __future__ import annotations

from pathlib import Path

import workbench

#: id of the depth table used when none is chosen: the 2023 T-Table
#: (Hona & Stephan 2024; ``data_tables/tissue_depth/ttable_2023.csv``)
DEFAULT_DEPTH_TABLE = "ttable_2023"


def data_tables_dir() -> Path:
    """The ``data_tables`` folder: the wheel's packaged copy first, else the checkout's."""
    package = Path(workbench.__file__).resolve().parent
    packaged = package / "_data" / "data_tables"
    return packaged if packaged.is_dir() else package.parent / "data_tables"
