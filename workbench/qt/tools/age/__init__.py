"""The "Age progression" tool: a head shown at another age, live under a slider.

The method is the service's (:func:`workbench.services.age.change.age_head`,
``workbench age``); this tool runs it in the window's worker and shows the
results.  Export runs the age pipeline
(:func:`workbench.pipelines.age.age_to_folder_with_report`), the function the
command line calls, so the folder holds what ``workbench age`` writes, report
and pictures included.  The export runs in the worker, but the report's
pictures are drawn with VTK, and worker threads never touch VTK
(ARCHITECTURE.md §3.4): the worker hands the picture and PDF writer to the GUI
thread (:class:`~workbench.qt.gui_call.GuiCall`) and waits for it, so the
folder is still written as one piece.

Live preview
------------
One age step takes ~1-2 s, so the slider does not wait for it.  The tool
keeps a cache of results for whole-year target ages (per source head and
settings).  When the slider moves it draws at once the **nearest computed
age** (no blending: every head drawn is a real result of the service, and the
dock and the view's caption say which age it is), and the worker computes
the slider's age, then the whole years around it (±:attr:`~workbench.qt.tools.age.tool.AgeTool.prefetch_years`),
one job at a time, the one closest to the slider first.  The aged skin
(same vertices and triangles as the source) is moved in place, so following
the slider costs one points update, not a new actor.

Before / after
--------------
"Side by side": the source head to the left of the aged one (shifted by its
width + :data:`~workbench.qt.tools.age.drawing.GAP_MM` along −x; the view looks at the faces from the
front).  "Overlay": both in place, the source translucent, the aged skin
coloured by each vertex's **displacement** from its source position (mm;
the two skins share vertices, so this is the vertex-to-vertex distance, not
a closest-surface distance).

Frames and units: mm, each head in its own Frankfort frame (x to the
subject's left, x = 0 midsagittal, y up, z toward the face); the aged heads
are settled in theirs, which shares axes and origin (between the porions)
with the source.  Not the case's skull frame; the tool's actors are its own,
not :data:`workbench.qt.scene.LAYERS`.

The case
--------
The case keeps the dock's *settings*, not its heads: "Keep in case" pushes
:class:`~workbench.commands.age_study.SetAgeStudy` with the dock's
:class:`~workbench.model.age_study.AgeStudy` (source, sex, ages, norms) on
the window's one undo stack, so Edit ▸ Undo takes it back and it is in the
audit log and the saved file.  When a case with a study is opened, or the
study changes by undo/redo, the dock shows its settings again (and ages the
head anew).  The case has no part holding a head (a reconstructed face is a
derived result of the window's session), so there is no "Apply": the heads
stay view only; Export… writes the aged head as a template pack (which
reconstructs, animates and ages again) with its report.

Modules: :mod:`~workbench.qt.tools.age.work` is the worker side (plain data, no
Qt, no VTK), :mod:`~workbench.qt.tools.age.tool` the controller (:class:`AgeTool`),
:mod:`~workbench.qt.tools.age.drawing` its drawing and
:mod:`~workbench.qt.tools.age.text` what the dock writes.
"""
