"""PyInstaller runtime hook: settings the frozen workbench needs before any import.

qtpy (used by pyvistaqt) is told to use PySide6, the only Qt binding the
bundle carries.  A value already set in the environment wins.

Caches of a frozen run are where a pip install keeps them, in the platform's
cache folder (``~/.cache`` on Linux): the workbench's reference heads and
samples under ``forensic-workbench/`` (platformdirs), numba's compiled
kernels under ``numba/`` (numba keys them by the executable when frozen),
Qt's and Mesa's shader caches under their own names.
"""

import os

os.environ.setdefault("QT_API", "pyside6")
