"""numba, when installed, with its compiled-kernel cache in the user's cache folder.

Kernels are compiled with ``cache=True``: once per machine, into
``<user cache>/forensic-workbench/numba`` rather than beside the installed
sources (numba's default when site-packages is writable).  A
``NUMBA_CACHE_DIR`` the user set wins.  :data:`numba` is ``None`` when the
package is missing; callers then run their numpy fallback.
"""

from __future__ import annotations

import os
from types import ModuleType


def _set_cache_dir() -> None:
    if "NUMBA_CACHE_DIR" not in os.environ:
        try:
            import platformdirs
        except ImportError:  # pragma: no cover - platformdirs is a dependency
            return
        base = platformdirs.user_cache_dir("forensic-workbench")
        os.environ["NUMBA_CACHE_DIR"] = os.path.join(base, "numba")


_set_cache_dir()
numba: ModuleType | None
try:
    import numba
except ImportError:  # pragma: no cover - numba is a dependency, this is the fallback
    numba = None
