"""The reconstruction folder's report pictures, drawn in-process or in the helper process.

What is drawn: the skull with its dowels, the face over the skull and alone,
in three views, the three build faces side by side and the 95 % band map
(:mod:`workbench.render.reconstruction`), all in the fitted head's frame and
in mm.  :class:`PictureScene` holds everything those pictures show as plain
meshes and arrays, so that it pickles: :func:`draw_scene` draws it wherever
it runs.

Why a second process: ``workbench reconstruct`` spent ~4 s of its ~18 s (on
an 817k-triangle CT bone, 2 cores) importing VTK and drawing, one after the
other with writing the meshes, the case and the report.
:class:`PicturesAside` imports VTK and draws in the helper process
(:mod:`workbench.core.helper_process`) while the job writes its other files;
only the PDF, which holds the pictures, waits for them.  (Importing VTK there
while the fit ran slowed the fit, which uses both cores, by about as much as
it saved.)  The helper runs at a lower priority, so the files the job
writes come first.  If the helper cannot draw (it could not start, or died),
the pictures are drawn here as before; a picture that fails to render is a
note, never a failed job.  The window does not use this: it draws on its own
GUI thread (``Draw`` in :mod:`workbench.pipelines.reconstruct`).
"""

from __future__ import annotations

import contextlib
import threading
from concurrent.futures import Future
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from workbench.core import helper_process
from workbench.core.errors import InputError
from workbench.core.mesh import Mesh

if TYPE_CHECKING:
    from workbench.services.reconstruction.job import JobResult

_HERE = "workbench.pipelines.pictures"


@dataclass(frozen=True)
class PictureScene:
    """What the report pictures show (mm; meshes and points in the skull file's frame).

    ``frame`` maps that frame into the fitted head's (Frankfort) frame, which
    the cameras use.  ``builds``: the build faces by name (with ``bmi`` and the
    ``main`` one), None without builds; ``band_mm``: the band's half-width per
    face vertex.
    """

    skull: Mesh
    face: Mesh
    dowels: tuple[np.ndarray, np.ndarray]
    frame: np.ndarray
    eyes: Mesh
    spread: np.ndarray | None
    inferred: np.ndarray | None
    builds: dict[str, Mesh] | None
    bmi: dict[str, float] | None
    main: str | None
    band_mm: np.ndarray | None


def _bare(mesh: Mesh) -> Mesh:
    """``mesh`` without its cached properties (a scene crosses to the helper as a pickle)."""
    return Mesh(mesh.vertices, mesh.faces)


def job_skull(result: JobResult) -> Mesh:
    """The case's skull mesh (mm, the skull file's frame); a job always has one."""
    mesh = result.opened.case.specimen.mesh
    if mesh is None:
        raise InputError("the case", "has no skull mesh", "open a skull before reconstructing")
    return mesh


def picture_scene(result: JobResult) -> PictureScene:
    """The scene of a job's pictures: the skull the face was fitted over (with the jaw in
    occlusion when the fit moved it there), the face, the dowels, the eyes, the build faces."""
    from workbench.services.reconstruction.reconstruct import articulated_skull

    recon = result.recon
    active = recon.plan.active()
    origins = recon.to_input(np.array([d.origin for d in active]))
    tips = recon.to_input(np.array([d.tip for d in active]))
    skull = job_skull(result)
    if recon.registration is not None and recon.registration.occlusion is not None:
        skull = articulated_skull(recon.registration)
    builds = result.fit.builds if result.fit is not None else None
    return PictureScene(
        skull=_bare(skull),
        face=_bare(recon.face),
        dowels=(origins, tips),
        frame=np.asarray(recon.input_to_head, float),
        eyes=_bare(recon.mesh_to_input(recon.head.meshes["eyes"])),
        spread=result.spread,
        inferred=recon.inferred,
        builds=None
        if builds is None
        else {name: _bare(builds.face(name, recon)) for name in builds.names},
        bmi=None if builds is None else dict(builds.bmi),
        main=None if builds is None else builds.main,
        band_mm=None if builds is None else builds.half_width_mm,
    )


@helper_process.runnable
def draw_scene(out_dir: str, scene: PictureScene) -> tuple[dict[str, Path], list[str]]:
    """Draw ``scene`` into ``out_dir``: ({name: path}, notes on pictures that could not be made).

    Without off-screen rendering no picture is made and a note says why; the
    build faces and the band map are drawn apart, so a failure there loses
    only those pictures.
    """
    from workbench.render.reconstruction import render_builds, render_reconstruction

    out, notes = Path(out_dir), []
    if not out.parent.is_dir():  # the job's folder is gone (the job was stopped meanwhile)
        return {}, [f"no pictures ({out.parent} no longer exists)"]
    try:
        paths = render_reconstruction(
            scene.skull,
            scene.face,
            scene.dowels,
            out,
            frame=scene.frame,
            eyes=scene.eyes,
            spread=scene.spread,
            inferred=scene.inferred,
        )
    except (RuntimeError, OSError, ValueError) as exc:
        return {}, [f"no pictures (off-screen rendering failed: {exc})"]
    if scene.builds is not None:
        try:
            paths |= render_builds(
                scene.builds,
                out,
                frame=scene.frame,
                bmi=scene.bmi,
                main=scene.main,
                eyes=scene.eyes,
                skull=scene.skull,
                band_face=scene.face,
                band_mm=scene.band_mm,
            )
        except (RuntimeError, OSError, ValueError, InputError) as exc:
            notes.append(f"no build pictures (rendering failed: {exc})")
    return paths, notes


def _in_helper(future: Future, name: str, *args: object) -> None:
    """Run ``name(*args)`` in the helper process on a thread of its own; the outcome into ``future``."""

    def work() -> None:
        try:
            future.set_result(helper_process.call(name, *args, fallback=False))
        except BaseException as exc:  # noqa: BLE001 - handed to the one who waits
            future.set_exception(exc)

    threading.Thread(target=work, name="job-pictures", daemon=True).start()


class PicturesAside:
    """The job's pictures drawn in the helper process while the job goes on (module docstring).

    :meth:`start` once the fit is done and the folder exists; :meth:`finish`
    where the report needs them.
    """

    def __init__(self) -> None:
        self._drawing: Future | None = None
        self._scene: PictureScene | None = None
        self._out: Path | None = None

    def start(self, out: Path, result: JobResult) -> None:
        """Start drawing ``result``'s pictures into ``out`` in the helper."""
        self._scene, self._out = picture_scene(result), out
        self._drawing = Future()
        _in_helper(self._drawing, f"{_HERE}:draw_scene", str(out), self._scene)

    def wait(self) -> None:
        """Wait until the helper is done with the folder (whatever came of it): a job that
        failed meanwhile removes the folder only then."""
        if self._drawing is not None:
            with contextlib.suppress(BaseException):
                self._drawing.exception()

    def finish(self) -> tuple[dict[str, Path], list[str]]:
        """Wait for the pictures: ({name: path}, notes on pictures not made); drawn here if
        the helper could not draw them."""
        if self._drawing is None or self._scene is None or self._out is None:
            return {}, []
        try:
            return self._drawing.result()
        except (RuntimeError, OSError, EOFError):  # the helper died or could not be reached
            return draw_scene(str(self._out), self._scene)
