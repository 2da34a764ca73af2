"""Build hook: ship ``data_tables/`` inside the package as ``workbench/_data/data_tables``.

In a source checkout (or an editable install) the tables are read from the
top-level ``data_tables/`` folder; in an installed wheel they are read from the
copy this hook makes.  All other metadata lives in ``pyproject.toml``.
"""

from __future__ import annotations

import shutil
from pathlib import Path

from setuptools import setup
from setuptools.command.build_py import build_py


class BuildWithTables(build_py):
    def run(self) -> None:
        super().run()
        source = Path(__file__).resolve().parent / "data_tables"
        target = Path(self.build_lib) / "workbench" / "_data" / "data_tables"
        if source.is_dir():
            shutil.rmtree(target, ignore_errors=True)
            shutil.copytree(source, target)


setup(cmdclass={"build_py": BuildWithTables})
