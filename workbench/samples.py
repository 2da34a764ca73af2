"""Public sample data (``workbench.samples.fetch("headsq")``); see :mod:`workbench.io.samples`."""

from __future__ import annotations

from workbench.io.samples import Sample, cache_dir, fetch, registry, resolve_input, seed_from_mirror

__all__ = ["Sample", "cache_dir", "fetch", "registry", "resolve_input", "seed_from_mirror"]
