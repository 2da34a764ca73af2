"""Pipelines: one input in, one finished output folder out, for each job of the workbench.

A pipeline runs a service (the fit, the scan fit, the age change, the
validation study), then writes everything the job delivers into one folder,
staged and renamed into place as a whole (:func:`workbench.io.outputs.staged_folder`):
the meshes, the pictures (render layer), the report (reporting layer), the
data credits.  The command line, the window and ``workbench batch`` all call
these functions, so the three write the same files for the same case; they
differ only in how they show progress and results (printing, a status bar,
a summary table).

Layer: above :mod:`workbench.render` and :mod:`workbench.reporting`, below
:mod:`workbench.qt` and :mod:`workbench.cli`; no Qt here.  Pictures are drawn
through a ``draw`` callable the caller may wrap (the window runs pipelines in
a worker thread and hands the VTK drawing to its GUI thread).

Modules: :mod:`~workbench.pipelines.reconstruct` (skull → face folder),
:mod:`~workbench.pipelines.scan_fit` (scan → fitted head pack),
:mod:`~workbench.pipelines.age` (head → aged heads), :mod:`~workbench.pipelines.validate`
(manifest of real CTs → figures), :mod:`~workbench.pipelines.batch` (a manifest of
jobs on Dask).  Units: mm; each output states its frame in its file header.
"""
