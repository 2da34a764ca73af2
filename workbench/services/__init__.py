"""Scriptable services: one capability package per tool, each called alike by the command
line, Python scripts and the window (which only adds drawing).

Packages, top to bottom (a package imports only those below it; the import-linter contract in
``pyproject.toml`` holds it):

* ``batch`` — many cases on a local pool or a Dask cluster;
* ``validation``, ``age`` — scoring against true skins; growth and ageing;
* ``reconstruction``, ``scan_fit``, ``animation`` — skull to face; a head fitted to a scan;
  muscles, expressions and speech;
* ``guides`` — nose, mouth and eye guides and published rules;
* ``tissue`` — tissue-depth dowels, the build model's depths, the tissue model;
* ``templates`` — the reference head, its packs, regions and muscles;
* ``case``, ``registration`` — opening and checking a case; the dense skull registration;
* ``landmarks`` — head frame, snapping, transfer;
* ``ct`` — CT and MR volumes to surfaces.

Units mm; heads in the Frankfort Horizontal frame unless a function says otherwise.
"""
