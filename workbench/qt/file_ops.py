"""File actions of the main window: open a skull mesh, a CT or a case; save; export.

A tool the main window composes (:class:`FileTool`, built from the
document, the session and the worker; the window is its
:class:`~workbench.qt.hosts.FileHost`: messages, dialogs' parent).  Reading and
extraction run in the worker (the window stays responsive); the new case
replaces the current one on the GUI thread.  Saving is synchronous and
atomic (:func:`workbench.io.case_file.save_case`): a failed save shows why
and leaves both the previous file and the open case as they were.
Everything in mm; a mesh whose size does not look like mm is refused by the
reader and the window asks for its units.
"""

from __future__ import annotations

import tempfile
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Any

from PySide6.QtWidgets import QFileDialog

from workbench.commands.stack import CommandStack
from workbench.core.errors import UnitsError, WorkbenchError
from workbench.core.raycast import RayCaster
from workbench.io.case_file import case_validator, load_case, save_case
from workbench.qt import autosave, dialogs
from workbench.qt.gui_call import GuiCall
from workbench.services.case.case_setup import OpenedCase, start_case_from_skull
from workbench.services.landmarks.snap import snap_index
from workbench.services.reconstruction import case_steps

if TYPE_CHECKING:
    from workbench.qt.ct_import import CtImportDialog
    from workbench.qt.document import Document
    from workbench.qt.hosts import FileHost
    from workbench.qt.session import Session
    from workbench.qt.workers import TaskRunner

MESH_FILTER = "Meshes (*.ply *.stl *.obj *.vtk *.vtp);;All files (*)"
CASE_FILTER = "Case files (*.fcase);;All files (*)"
CT_FILTER = "Volumes (*.nhdr *.nrrd *.mha *.mhd *.nii *.nii.gz);;All files (*)"
#: the mesh formats of the window's export (PLY always; OBJ and STL for the tools artists use)
EXPORT_FORMATS = ("ply", "obj", "stl")


def _with_orientation(opened: OpenedCase, source: Path, space: str | None = None) -> OpenedCase:
    """Record the known anatomy directions of a public sample (not an undo step).

    ``space``: the frame the sample's numbers were written in ("LPS": the case
    reads them with x and y negated, as :func:`workbench.io.meshes.read_mesh` does).
    """
    import numpy as np

    from workbench.commands.reconstruction_setup import SetOrientation
    from workbench.io.meshes import to_read_frame

    anatomy = case_steps.sample_orientation(source)
    if anatomy is not None:
        anatomy = {k: to_read_frame(np.asarray(v), space).tolist() for k, v in anatomy.items()}
    if anatomy is not None and opened.case.orientation is None:
        opened.stack.push(
            SetOrientation(
                case_steps.anatomy_orientation(anatomy), label="Orientation of the sample file"
            )
        )
        opened.stack.clear()
        opened.stack.set_clean()
        opened.notes.append(
            f"{source.name}: a known sample; face toward "
            f"{anatomy['anterior']}, up {anatomy['superior']} (file axes)"
        )
    return opened


def _drawable(opened: Any) -> Any:
    """Worker side: the skull's vertex normals, snap index and ray-casting scene,
    cached on the mesh.

    ``opened`` is an ``OpenedCase`` or a loaded case file; either has
    ``.case``.  Spares the GUI thread ~50 ms (drawing) and ~0.1 s (first
    Snap) on a 100k-triangle skull.  The ray-casting scenes (~110-160 ms,
    in steps that hold the GIL for ~25 ms each) are built here, before the
    skull is drawn; every fit's frame-aligned copy of the skull borrows
    them (:meth:`RayCaster.shared`).
    """
    mesh = opened.case.specimen.mesh
    if mesh is not None and mesh.n_faces:
        _ = mesh.vertex_normals
        snap_index(mesh).warm()  # the first Snap then takes ms, not ~0.1 s
        RayCaster.shared(mesh)
    case_validator()  # (~75 ms, else paid by the first Save on the GUI thread)
    return opened


def _with_stored_fit(loaded: Any) -> tuple[Any, Any, str]:
    """Worker side: ``(loaded, stored fit or None, why it could not be read or "")``.

    The face a case file keeps (:mod:`workbench.services.reconstruction.stored_fit`) is
    decoded here, with its inputs checked against the case's (current or stale).
    """
    from workbench.services.reconstruction import stored_fit

    state = loaded.case.derived.get(stored_fit.KEY)
    if state is None:
        return loaded, None, ""
    try:
        return loaded, stored_fit.fit_from_state(state, loaded.case), ""
    except stored_fit.StoredFitError as exc:
        return loaded, None, str(exc)


def case_from_ct(
    path: Path,
    tissue: str,
    iso: float | None,
    *,
    volume: Any = None,
    progress: Callable[[str, float], None] | None = None,
) -> OpenedCase:
    """Worker side of "Open CT": surface (mm, CT frame) → PLY in a temporary folder → new case.

    ``iso`` in the volume's units (None: the ``tissue`` preset); ``volume``
    the already read volume of ``path``.  ``progress(step, fraction)`` may
    raise :class:`~workbench.core.errors.Cancelled` to stop the job.
    """
    from workbench.io.meshes import write_mesh
    from workbench.services.ct.ct_mesh import mesh_from_ct

    def report(step: str, fraction: float) -> None:
        if progress is not None:
            progress(step, fraction)

    result = mesh_from_ct(
        path if volume is None else volume,
        tissue,
        iso=iso,
        progress=lambda step, f: report(step, 0.7 * f),
    )
    report("writing the surface", 0.71)
    folder = Path(tempfile.mkdtemp(prefix="workbench-ct-"))
    stem = path.name.split(".")[0]
    # tagged with the CT's frame: read back as RAS like any LPS-tagged mesh, so the case, its
    # landmark files and report (RAS) lie on the CT in 3D Slicer
    surface = write_mesh(folder / f"{stem}_{tissue}.ply", result.mesh, space=result.frame)
    report("starting the case", 0.74)
    opened = start_case_from_skull(surface, units="mm")
    opened.notes.insert(
        0,
        f"{tissue} surface of {path} at iso {result.iso:g} "
        f"{result.units} ({result.rule}), frame {result.frame}"
        + (" (read as RAS: x and y negated)" if result.frame == "LPS" else ""),
    )
    report("orientation", 0.97)
    opened = _with_orientation(opened, path, result.frame)
    report("done", 1.0)
    return opened


class FileTool:
    """Open/save/export for the main window (see the module docstring).

    Attributes
    ----------
    exported : dict[str, Path]
        The files of the last export.
    ct_dialog : CtImportDialog or None
        The last CT import dialog opened.
    """

    def __init__(
        self, document: Document, session: Session, runner: TaskRunner, host: FileHost
    ) -> None:
        self.document = document
        self.session = session
        self.runner = runner
        self.host = host
        self.exported: dict[str, Path] = {}
        #: the export's report pictures are drawn on the GUI thread (VTK)
        self.gui_call = GuiCall()
        self.ct_dialog: CtImportDialog | None = None

    def status(self, text: str) -> None:
        self.host.status(text)

    def show_error(self, what: str, exc: BaseException) -> None:
        self.host.show_error(what, exc)

    # ------------------------------------------------------------ open
    def open_skull(self, path: str | Path, units: str = "auto", scale: float | None = None) -> None:
        """Start a new case from a skull mesh (in the worker)."""
        if not self.may_discard():
            return
        path = Path(path)
        self.runner.submit(
            "open",
            f"Opening {path.name} …",
            lambda: _drawable(
                _with_orientation(start_case_from_skull(path, units=units, scale=scale), path)
            ),
            lambda opened: self.replace_case(opened, None),
            lambda exc: self._open_failed(path, exc),
        )

    def _open_failed(self, path: Path, exc: BaseException) -> None:
        if isinstance(exc, UnitsError) and self.host.interactive:
            factor = dialogs.ask_units(self.host.window(), path.name, exc.problem)
            if factor is not None:
                self.open_skull(path, scale=factor)
            return
        self.show_error(f"Could not open {path.name}", exc)

    def open_ct(
        self,
        path: str | Path,
        tissue: str = "bone",
        iso: float | None = None,
        *,
        volume: Any = None,
        finished: Callable[[bool], None] | None = None,
    ) -> bool:
        """Extract the bone surface of a CT (worker, channel "open") and start a case from it.

        The extracted surface (mm, the CT's physical frame) is the case's
        evidence file; the CT itself stays where it is.  ``iso`` is in the
        volume's units (HU for CT); None uses the ``tissue`` preset.
        ``volume`` is the already read :class:`~workbench.core.volume.Volume`
        of ``path`` (the import dialog's), so it is not read again.  The job
        reports progress and can be cancelled with ``runner.cancel("open")``
        (the case is then unchanged).  ``finished(ok)`` is called after the
        new case is shown (True) or the error was shown (False); never after
        a cancel.  Returns False if the user kept the current case.
        """
        if not self.may_discard():
            return False
        path = Path(path)

        def done(opened: OpenedCase) -> None:
            self.replace_case(opened, None)
            if finished is not None:
                finished(True)

        def failed(exc: BaseException) -> None:
            self.show_error(f"Could not open the CT {path.name}", exc)
            if finished is not None:
                finished(False)

        self.runner.submit(
            "open",
            f"Extracting the {tissue} surface of {path.name} …",
            lambda progress: _drawable(
                case_from_ct(path, tissue, iso, volume=volume, progress=progress)
            ),
            done,
            failed,
            progress=True,
        )
        return True

    def open_ct_dialog(self, path: str | Path) -> Any:
        """Show the non-modal CT import dialog (threshold preview, then extraction)."""
        from workbench.qt.ct_import import CtImportDialog

        previous = self.ct_dialog
        if previous is not None and previous.isVisible():
            previous.close()  # both would use the same worker channels
        dialog = CtImportDialog(self.host, path)
        self.ct_dialog = dialog
        dialog.show()
        return dialog

    def open_case(self, path: str | Path) -> None:
        """Open a saved ``.fcase`` (in the worker)."""
        if not self.may_discard():
            return
        path = Path(path)
        self.runner.submit(
            "open",
            f"Opening case {path.name} …",
            lambda: _with_stored_fit(_drawable(load_case(path))),
            lambda opened: self._opened_case(opened, path),
            lambda exc: self.show_error(f"Could not open {path.name}", exc),
        )

    def _opened_case(self, opened: tuple[Any, Any, str], path: Path) -> None:
        """A loaded case file in the window, with its integrity and face notes.

        A case that fails its evidence, array or audit-chain check never gets
        here: loading refuses it and the error names the first problem.  A
        face kept in the file is shown at once (``host.restore_fit``).
        """
        loaded, stored, problem = opened
        self.replace_case(OpenedCase(loaded.case, CommandStack(loaded.case)), path)
        chain = loaded.audit_chain.summary()
        audit = chain if chain.startswith("audit log") else f"audit log {chain}"
        notes = [
            f"{path.name}: evidence and arrays match their hashes; {audit}; "
            f"case.json {loaded.content_seal.summary()}"
        ]
        if problem:
            notes.append(f"{path.name}: the face kept in the file was not shown: {problem}")
        elif stored is None and "template_hash" in loaded.case.parameters:
            notes.append(
                f"{path.name} was reconstructed before, but the file keeps the settings, not "
                "the face: Reconstruct face (Ctrl+R) fits it again"
            )
        for note in notes:
            self.host.messages.append(note)
        self.status(f"{self.host.status_text()}; {audit}")
        if stored is not None:
            self.host.restore_fit(stored)

    def replace_case(self, opened: OpenedCase, path: Path | None) -> None:
        """Show ``opened`` as the window's case (``path``: its file; None: untitled)."""
        self.session.clear_fit()
        self.document.replace(opened.case, opened.stack, path, opened.notes)
        for note in opened.notes:
            self.host.messages.append(note)
        self.status(
            f"Opened {path.name if path else 'a new case'}: "
            f"{opened.case.specimen.mesh.n_faces if opened.case.specimen.mesh else 0} "
            "triangles"
        )

    # ------------------------------------------------------------ save
    def save(self) -> bool:
        if self.document.path is None:
            return self.ask_save_as()
        return self.save_to(self.document.path)

    def save_to(self, path: str | Path) -> bool:
        """Save atomically; on failure the old file and the open case are unchanged."""
        path = Path(path)
        if path.suffix != ".fcase":
            path = path.with_suffix(".fcase")
        try:
            save_case(self.document.case, path, self.document.stack)
        except (WorkbenchError, OSError) as exc:
            self.show_error(f"Could not save to {path}", exc)
            return False
        self.document.path = path
        self.document.stack_changed.emit()
        autosave.forget_snapshot(self.host)  # the saved file now holds the work
        self.status(f"Saved {path}")
        return True

    def ask_save_as(self) -> bool:
        start = str(self.document.path or "case.fcase")
        name, _ = QFileDialog.getSaveFileName(
            self.host.window(), "Save case as", start, CASE_FILTER
        )
        return self.save_to(name) if name else False

    # ------------------------------------------------------------ export
    def export_to(self, folder: str | Path, force: bool = False) -> bool:
        """The reconstruction folder ``workbench reconstruct`` writes, into ``folder`` (worker).

        :func:`workbench.pipelines.reconstruct.export_fit`: the face (and the
        build faces) and the fitted head in PLY, OBJ and STL, landmarks, the
        case, ``report.pdf`` with its pictures (drawn on the GUI thread).  A
        folder that is not empty is replaced only when the user confirms (the
        old one is kept as ``DIR.1``).  False when refused at once.
        """
        from workbench.pipelines.reconstruct import export_fit, reconstruction_pictures
        from workbench.qt.tools.common import folder_is_free

        case, fit, notes = self.document.case, self.session.fit, list(self.document.notes)
        out = Path(folder)
        if fit is None:
            self.status("Nothing to export yet: reconstruct the face first (Reconstruct).")
            return False
        if not force and not folder_is_free(out):
            if not (
                self.host.interactive
                and dialogs.ask_replace_folder(self.host.window(), out, "the reconstruction")
            ):
                self.status(f"Not exported: {out} already exists and is not empty.")
                return False
            force = True
        draw = self.gui_call.wrap(reconstruction_pictures, None, "drawing the report's pictures")
        kept: list[str] = []
        self.runner.submit(
            "export",
            f"Exporting to {out} …",
            lambda: (
                export_fit(
                    case,
                    fit,
                    out,
                    notes=notes,
                    formats=EXPORT_FORMATS,
                    draw=draw,
                    force=force,
                    notify=kept.append,
                ).files
            ),
            lambda files: self._exported(files, kept),
            lambda exc: self.show_error(f"Could not export to {out}", exc),
        )
        return True

    def _exported(self, files: dict[str, Path], notes: list[str] | None = None) -> None:
        self.exported = files
        for note in notes or ():
            self.host.messages.append(note)
        folders = sorted({str(p.parent) for p in files.values()}, key=len)
        where = f" into {folders[0]}" if folders else ""
        kinds = sorted({key.split("/")[0].split("_")[0] for key in files})
        self.status(f"Exported {len(files)} files{where}: {', '.join(kinds)}")

    # ------------------------------------------------------------ dialogs
    def ask_open_skull(self) -> None:
        name, _ = QFileDialog.getOpenFileName(
            self.host.window(), "Open skull mesh", "", MESH_FILTER
        )
        if name:
            self.open_skull(name)

    def ask_open_ct(self) -> None:
        name, _ = QFileDialog.getOpenFileName(
            self.host.window(), "Open CT volume (or cancel for a DICOM folder)", "", CT_FILTER
        )
        if not name:
            name = QFileDialog.getExistingDirectory(self.host.window(), "Open DICOM folder")
        if name and self.host.interactive:
            self.open_ct_dialog(name)
        elif name:
            self.open_ct(name)

    def ask_open_case(self) -> None:
        name, _ = QFileDialog.getOpenFileName(self.host.window(), "Open case", "", CASE_FILTER)
        if name:
            self.open_case(name)

    def ask_export(self) -> None:
        """Ask for the export folder (a new name is fine), starting in the case's folder."""
        if self.session.fit is None:
            self.status("Nothing to export yet: reconstruct the face first (Reconstruct).")
            return
        case_path = self.document.path
        stem = Path(case_path).stem if case_path is not None else "case"
        suggested = dialogs.start_folder(case_path) / f"{stem}_reconstruction"
        name = dialogs.ask_new_folder(
            self.host.window(), "Export the reconstruction into a folder", suggested
        )
        if name:
            self.export_to(name)

    def ask_load_truth(self) -> None:
        name, _ = QFileDialog.getOpenFileName(
            self.host.window(), "True skin surface (same frame, mm)", "", MESH_FILTER
        )
        if name:
            self.host.load_truth(name)

    def ask_screenshot(self) -> None:
        name, _ = QFileDialog.getSaveFileName(
            self.host.window(), "Save window picture", "window.png", "PNG (*.png)"
        )
        if name:
            self.host.save_screenshot(name)

    def may_discard(self) -> bool:
        """True if the open case may be replaced (saved, discarded, or clean)."""
        if not self.document.is_dirty or not self.host.interactive:
            return True
        answer = dialogs.ask_save_changes(
            self.host.window(),
            self.document.path.name if self.document.path else "the untitled case",
        )
        if answer == dialogs.QMessageBox.StandardButton.Save:
            return self.save()
        if answer == dialogs.QMessageBox.StandardButton.Discard:
            autosave.forget_snapshot(self.host)  # a deliberate discard
            return True
        return False
