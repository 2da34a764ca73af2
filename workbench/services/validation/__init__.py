"""Validation. Validation against true skins: the project's metric beside the uniform offset on
manifests of real skull/skin pairs (``run``), per-feature errors against true soft-tissue
landmarks (``features``) and surface comparison with region figures (``compare``).

May import: core, model, io, and ``reconstruction``, ``templates``, ``guides``, ``tissue``.
"""
