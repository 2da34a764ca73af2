"""Guides. Nose, mouth and eye guides: Kähler's classic rules (``classic``), measurements on
the bone (``measure``), published prediction rules and the defaults chosen by validation
(``rules``), and the set a fit uses with its plausibility checks (``fit_guides``).

May import: core, model, io, ``tissue``, ``templates``.
"""
