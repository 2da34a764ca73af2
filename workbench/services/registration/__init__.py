"""Skull registration. The reference skull registered densely onto a target bone: orientation,
pieces, mandible pose and the self-check (``skull_registration``), the checks of a skull
mesh before (``skull_check``) and the jaw's articulation (``jaw``).

May import: core, model, io, ``landmarks``, ``templates``.
"""
