"""Visuals: what the window's 3D views show, built from plain data into a ``pyvista.Plotter``.

A visual is a function that turns plain data (a :class:`~workbench.core.mesh.Mesh`,
``(n, 3)`` point arrays, per-vertex values) into pyvista data and actors with their
look fixed here: colours, opacities, point sizes, line widths, colour bars, actor
names, pickability and ``render=False`` (the caller's view decides when to paint).
Units are mm; a visual draws in whatever frame its data arrive in (the specimen's
input frame in the main view, the head frame in the guide view and the age and
animate tools, the scan's frame in the scan-fit tool, the CT's physical frame in the
CT preview) and never transforms between frames; :mod:`.orientation` reflects how a
view *shows* a frame that is a mirror image of the subject (never the data), so every
view has one handedness, and names the subject's sides at a view's edges.  The caller
(the Qt window) decides when to draw, which layer an actor belongs to, its visibility
and opacity, and removes actors; a plotter here is any ``pyvista.Plotter`` (pyvistaqt's
view is one).  This package may import pyvista, VTK, numpy and the layers below render
(core, model, services, io) — never Qt (PySide6, pyvistaqt) nor :mod:`workbench.qt`.
"""
