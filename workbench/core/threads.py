"""How many threads the workbench's own parallel loops may use.

The chunked warps and nearest-point queries (:mod:`workbench.core.tps`,
:mod:`workbench.core.spatial`, scipy's k-d trees) run on a thread pool.  By
default it has one thread per core; ``WORKBENCH_THREADS`` (or, failing that,
``OMP_NUM_THREADS``, which ``workbench batch`` sets to 1 in its worker
processes so that N workers on N cores do not fight over them) caps it.
"""

from __future__ import annotations

import os


def worker_count() -> int:
    """Threads for one parallel loop: the cores, capped by the environment (≥ 1)."""
    cores = os.cpu_count() or 1
    for name in ("WORKBENCH_THREADS", "OMP_NUM_THREADS"):
        value = os.environ.get(name, "").strip()
        if value:
            try:
                return max(1, min(cores, int(value)))
            except ValueError:
                continue
    return cores


#: a k-d query of fewer points than this runs on the calling thread: scipy starts its
#: worker threads anew on every call, which costs more than the query below this size
SMALL_QUERY = 20_000


def query_workers(n_points: int) -> int:
    """Threads for one k-d tree query of ``n_points`` points (1 for small queries)."""
    return 1 if n_points < SMALL_QUERY else worker_count()
