"""pyvista visuals and off-screen snapshots; no Qt widgets.

VTK is imported when this package is (:func:`load_vtk`), with Ctrl-C held
back: a ``KeyboardInterrupt`` inside VTK's module initialisation left the
process to die of a segmentation fault later (exit 139 instead of 130).  A
command that makes pictures after a long job may also call :func:`load_vtk`
before the job starts.
"""

from __future__ import annotations

import importlib

from workbench.core.cancel import interrupts_deferred

#: what an off-screen picture imports: pyvista, its plotting package (which loads
#: VTK's rendering, OpenGL, text and image-writer modules) and the two VTK modules it
#: loads later, on the first plotter
VTK_MODULES = (
    "pyvista",
    "pyvista.plotting",
    "vtkmodules.vtkInteractionWidgets",
    "vtkmodules.vtkViewsContext2D",
)


def load_vtk() -> str | None:
    """Import :data:`VTK_MODULES` with Ctrl-C held back until they are in
    (:func:`workbench.core.cancel.interrupts_deferred`).

    Returns None when they are, else why not (no pyvista, no OpenGL library):
    the pictures' own imports then report it as before.
    """
    with interrupts_deferred():
        for name in VTK_MODULES:
            try:
                importlib.import_module(name)
            except (ImportError, OSError) as exc:
                return f"{name}: {exc}"
    return None


load_vtk()
