"""The "Fit scan" tool: open a face scan, fit the reference head, assist landmarks.

The fit is the service's (:func:`workbench.services.scan_fit.fit.fit_scan`,
``workbench fit-scan``), run in the window's worker with progress and
cancel; "Save pack…" runs :func:`~workbench.services.scan_fit.pack.fit_scan_pack`
with the same inputs (the scan file, its units, the landmarks the user
placed, sex, table, build), which refuses an existing folder unless the
user confirms.

Frames and units: mm.  The 3D view shows the scan in **its own input frame**
(the scan file's coordinates after units), so the fitted skin and its
landmarks are mapped back with :meth:`ScanFit.to_input`.  The scan is
coloured by each vertex's distance to the fitted skin (0–2.5 mm; grey where
the service does not count it: outside the face, at hole rims, not the head),
or, when the file carries colours (PLY / OBJ vertex colours, an OBJ texture
through its material's ``map_Kd``), in its own colours: the dock's "Scan
colours" choice, the scan's own colours by default (the person is recognised,
and lid, lip and brow landmarks placed, on them; the distance map checks the
fit).  The fitted skin then carries the scan's colours as the pack's does
(:func:`~workbench.qt.tools.scan_fit.work.skin_colours`).  A colour problem (a
missing texture image) never stops the scan from opening: the dock says it.

Landmarks (skin, the reference head's codes): the fit's landmarks are the
*first guess* (orange; violet over holes, where the service marks them
absent).  The user places a landmark by clicking the scan (code chosen in
the panel), drags the selected one, accepts the guess of one or all; these
*placed* landmarks (green) seed "Fit again" (3 or more orient the scan).

Undo: the placements are not part of the case (the case's landmark sets are in
the skull specimen's frame and a scan is not part of a case; holding it there
needs a new model part), but their changes are steps of the window's one undo
stack: each place, move, drag, remove, accept or accept-all is an
:class:`~workbench.qt.tools.scan_fit.state.EditScanLandmarks` command pushed on
the document's stack, labelled "… (scan fit)", so Edit ▸ Undo (Ctrl+Z), the
dock's own Undo / Redo buttons and the case's audit log all see them, in order
with the case's edits.  Such a step changes the audit log, not the case's parts,
and marks the case modified like any other step.  Opening another scan leaves
the steps made on the previous one on the stack, where they no longer act.

Modules: :mod:`~workbench.qt.tools.scan_fit.work` is the worker side
(:func:`read_scan`, :func:`run_scan_fit`, :func:`save_pack`: plain data, no Qt,
no VTK), :mod:`~workbench.qt.tools.scan_fit.state` the tool's plain data (shared
with its panel), :mod:`~workbench.qt.tools.scan_fit.tool` the GUI side
(:class:`ScanFitTool`: drawing, picking, dialogs).
"""
