"""The window's tools: one controller per tool dock.

A tool is the controller behind one dock of the main window (reconstruct,
skull landmarks, scan fit, animate, age progression; the live drags serve the
landmark and guide editing).  It reads its panel's choices, runs **one
service** (``workbench.services.*``) in the window's worker
(:class:`workbench.qt.workers.TaskRunner`, often through a plain function of
:mod:`workbench.services.reconstruction.case_steps` or of its own worker module), and draws the result
through the scene (:class:`workbench.qt.scene.SceneView`, or actors it owns in
the same plotter).  Edits of the case are commands pushed on the document's one
undo stack (:class:`workbench.qt.document.Document`); derived results live in
the window's :class:`~workbench.qt.session.Session`.

What a tool may import: the layers below Qt (``services``, ``commands``,
``io``, ``model``, ``core``, ``render``), the panels it reads and fills
(``workbench.qt.panels.*``), and the window's shared pieces (``scene``,
``guide_view``, ``workers``, ``jobs``, ``relay``, ``dialogs``, ``picking``,
``lod``, ``document``, ``session``, ``hosts``, ``file_ops`` for its file
filters, and :mod:`workbench.qt.tools.common`).
Not another tool, not :mod:`workbench.qt.main_window` (it reaches the window
through a small host protocol), never ``workbench.cli``.
"""
