"""The "Animate" tool's controller: the dock's parameters, the live timer, the timeline.

See :mod:`workbench.qt.tools.animate` for what the tool shows and how a track is
played and scrubbed; the drawing is :mod:`~workbench.qt.tools.animate.drawing`.
"""

from __future__ import annotations

import math
import time
from pathlib import Path
from typing import TYPE_CHECKING, Any, Protocol

import numpy as np
from PySide6.QtCore import QObject, QTimer, Signal

from workbench.core.errors import WorkbenchError
from workbench.qt.tools.animate.drawing import ALWAYS_SHOWN, AnimateDrawing, load_animator
from workbench.qt.tools.common import CaseLayersAside

#: the session's heads the dock animates, as the status line names them
SESSION_WHAT = {
    "reconstruction": "the reconstruction",
    "scan": "the fitted scan",
    "aged": "the aged head",
}

if TYPE_CHECKING:
    from PySide6.QtWidgets import QWidget

    from workbench.model.template import TemplateHead
    from workbench.qt.panels.animate_panel import AnimatePanel
    from workbench.qt.scene import SceneView
    from workbench.qt.workers import TaskRunner
    from workbench.services.animation.animator import Animator
    from workbench.services.animation.track import Key, Track, TrackFrames

#: the worker channel of head loading (a newer load supersedes the older)
CHANNEL = "animate"
#: timer interval and simulation steps per frame (the reference skin: ~17 ms of stepping)
FRAME_MS = 30
STEPS_PER_FRAME = 10
#: the skin has settled when no vertex moves more than this (mm) in a frame ...
SETTLED_MM = 2e-3
#: ... for this many frames in a row
SETTLED_FRAMES = 3
#: memory for a track's frame checkpoints (positions + velocities of every skin node)
CHECKPOINT_BUDGET_BYTES = 96 * 2**20
#: length of a track started by "Record keyframe" with no track loaded (seconds)
NEW_TRACK_S = 2.0


class AnimateHost(Protocol):
    """What the tool uses of the window: status line, readable errors."""

    def status(self, text: str) -> None: ...

    def show_error(self, what: str, exc: BaseException) -> None: ...

    def window(self) -> QWidget: ...


class AnimateTool(QObject, AnimateDrawing):
    """The "Animate" tool: see :mod:`workbench.qt.tools.animate`.

    Signals
    -------
    loaded()    a head was loaded (``animator`` is set)
    settled()   the timer stopped: the skin is at rest for the current parameters
    frame_shown(int)  the timeline stopped on this track frame (scrubbed or paused there)
    """

    loaded = Signal()
    settled = Signal()
    frame_shown = Signal(int)

    def __init__(
        self,
        panel: AnimatePanel,
        scene: SceneView,
        plotter: Any,
        runner: TaskRunner,
        host: AnimateHost,
        parent: QObject | None = None,
    ) -> None:
        super().__init__(parent)
        self.panel, self.scene, self.plotter = panel, scene, plotter
        self.runner, self.host = runner, host
        self.animator: Animator | None = None
        #: the session's own heads offered for animation (key of SESSION_WHAT → head)
        self._session_heads: dict[str, TemplateHead] = {}
        #: the dock is in front (its head shown, the case's layers set aside)
        self.active = False
        self._aside = CaseLayersAside(scene)
        self.sex = ""
        self._loading = ""
        self._actors: dict[str, Any] = {}
        self._points: np.ndarray | None = None  # the skin as drawn (mm)
        self._jaw_drawn = 0.0
        self._quiet_frames = 0
        #: milliseconds per timer frame (stepping + moving the points), newest last
        self.frame_ms: list[float] = []
        #: largest vertex move (mm) of the last frame
        self.last_move_mm = 0.0
        self.timer = QTimer(self)
        self.timer.setInterval(FRAME_MS)
        self.timer.timeout.connect(self.tick)
        panel.head_changed.connect(self.load)
        panel.expression_changed.connect(self.set_expression)
        panel.muscle_changed.connect(self.set_muscle)
        panel.jaw_changed.connect(self.set_jaw)
        panel.relax_requested.connect(self.relax)
        panel.bones_toggled.connect(self._show_inner)
        panel.gaze_changed.connect(self.set_gaze)
        panel.lids_changed.connect(self.set_lids)
        panel.open_track_requested.connect(self._ask_open_track)
        panel.save_track_requested.connect(self._ask_save_track)
        panel.record_requested.connect(self.record_key)
        panel.frame_requested.connect(self.seek)
        panel.play_toggled.connect(lambda on: self.play() if on else self.pause())
        panel.loop_toggled.connect(self.set_loop)
        panel.length_changed.connect(self.set_length)
        panel.frame.sliderReleased.connect(self._scrub_released)
        self._faces: dict[str, np.ndarray] = {}  # triangles of the drawn parts
        self._vf: dict[str, Any] = {}
        self._gaze_drawn = (0.0, 0.0)
        self._preset: tuple[str, float] | None = None  # the last preset applied (Record)
        # ---- timeline
        #: the track on the timeline (None: none), the file it came from (never overwritten)
        self.track: Track | None = None
        self.track_path: Path | None = None
        self._saved_as: Path | None = None
        #: its per-frame parameters for the loaded head's muscle order
        self.frames: TrackFrames | None = None
        #: the timeline's frame (the slider)
        self.position = 0
        #: the track frame the simulated skin is in (None: off the track, e.g. a slider moved)
        self.frame: int | None = None
        self.playing = False
        self.loop = False
        #: milliseconds per played frame (simulating or restoring + moving the drawn points;
        #: the render runs after it), newest last
        self.play_ms: list[float] = []
        #: milliseconds from one played frame to the next (the render and event loop included)
        self.play_interval_ms: list[float] = []
        self._last_tick: float | None = None
        self._checkpoints: dict[int, tuple[np.ndarray, np.ndarray]] = {}
        self._stride = 1
        self._target: int | None = None
        self.track_timer = QTimer(self)
        self.track_timer.setInterval(0)
        self.track_timer.timeout.connect(self._track_tick)

    # ------------------------------------------------------------ in front or left
    def set_active(self, on: bool) -> None:
        """The dock was shown (the head loaded and shown, the case's layers set aside) or
        left (the head hidden, the case's layers back, the simulation and the timeline
        stopped): the tool's head never stays in the view of another tool (issue 33)."""
        self.active = bool(on)
        self._aside.set_aside(self.active)
        if not self.active:
            self.timer.stop()
            if self.playing:
                self.pause()
        skin = self._actors.get("skin")
        if skin is not None:
            skin.SetVisibility(self.active)
        for part in ALWAYS_SHOWN:  # the eyes go with the head (they stayed behind before)
            actor = self._actors.get(part)
            if actor is not None:
                actor.SetVisibility(self.active)
        self._show_inner(self.active and self.panel.bones.isChecked())
        if self.active:
            self.ensure_loaded()
            if self.animator is not None:  # the case's hair as the Appearance dock has it now
                self.draw_hair()
        else:
            for key, actor in self._actors.items():
                if key.startswith("hair_"):
                    actor.SetVisibility(False)

    # ------------------------------------------------------------ loading
    def ensure_loaded(self) -> None:
        """Load the panel's head unless it is loaded or on its way (the dock was opened)."""
        if self.animator is None and not self._loading:
            self.load(self.panel.sex())

    def load(self, sex: str) -> None:
        """Load a reference head (``"male"``, ``"female"``) or the case's reconstruction
        (``"reconstruction"``: the fitted head, in its head frame) in the worker."""
        if sex == self._loading or (sex == self.sex and self.animator is not None):
            return
        if sex in SESSION_WHAT:
            head = self._session_heads.get(sex)
            if head is None:
                self.panel.show_status(f"There is no {SESSION_WHAT[sex].removeprefix('the ')}.")
                return
            from workbench.services.animation.animator import Animator

            what, job = SESSION_WHAT[sex], lambda: Animator(head)
        else:
            what, job = f"the reference {sex} head", lambda: load_animator(sex)
        self._loading = sex
        self.panel.show_status(f"Loading {what} …")

        def done(anim: Animator) -> None:
            self._loaded(sex, anim)

        self.runner.submit(CHANNEL, f"Loading {what} for animation …", job, done, self._failed)

    def offer_head(self, key: str, head: TemplateHead | None, title: str | None = None) -> None:
        """One of the session's heads changed (``key`` of :data:`SESSION_WHAT`: the case's
        reconstruction, the fitted scan, the aged head): offer it, and reload it if it is
        the one shown (as ``workbench animate`` takes a reconstruction, a fit-scan pack or
        an aged head)."""
        if head is None:
            self._session_heads.pop(key, None)
        else:
            self._session_heads[key] = head
        self.panel.offer_head(key, head is not None, title)
        if self.sex == key and head is not None and self.animator is not None:
            self.sex = ""  # a new head: the one shown is out of date
            self.load(key)

    def fit_changed(self, head: TemplateHead | None) -> None:
        """The case's fitted head changed: offer it, and reload it if it is the one shown."""
        self.offer_head("reconstruction", head)

    def fitted_head(self) -> TemplateHead | None:
        """The case's fitted head (head frame, mm), or None before a fit."""
        return self._session_heads.get("reconstruction")

    def _failed(self, exc: BaseException) -> None:
        self._loading = ""
        self.panel.show_status("The head could not be loaded.")
        self.host.show_error("Could not load the head to animate", exc)

    def _loaded(self, sex: str, anim: Animator) -> None:
        if sex != self._loading or self.scene.closed:
            return  # superseded, or the window closed
        self._loading = ""
        self.timer.stop()
        self.animator, self.sex = anim, sex
        self.panel.set_muscles(anim.muscle_codes)
        self.draw()
        if not self.active:  # loaded while another tool is in front: drawn, not shown
            for actor in self._actors.values():
                actor.SetVisibility(False)
        self.reset_camera()
        what = "The reconstruction" if sex == "reconstruction" else f"Reference {sex} head"
        self.panel.show_status(
            f"{what}: {len(anim.head.skin.vertices):,} skin vertices, "
            f"{len(anim.muscle_codes)} muscles."
        )
        self.host.status(f"Animate: {what.lower()} (view only: the case is not changed).")
        self.loaded.emit()
        if self.track is not None:  # opened before the head was there: frames for its muscles
            self.set_track(self.track, self.track_path)
            return
        name = self.panel.expression_name()
        if name and name != "neutral":
            self.set_expression(name, self.panel.weight())

    # ------------------------------------------------------------ parameters
    def set_expression(self, name: str, weight: float = 1.0) -> None:
        """Replace every muscle and the jaw with the preset ``name`` at ``weight`` (0..1)."""
        anim = self.animator
        if anim is None or not name:
            return
        self._leave_track()
        anim.set_expression(name, weight)
        self._preset = (name, float(weight))
        self._show_state()
        self._start()

    def set_muscle(self, code: str, contraction: float) -> None:
        anim = self.animator
        if anim is None:
            return
        self._leave_track()
        anim.set_muscles({code: float(contraction)})
        self._start()

    def set_jaw(self, degrees: float) -> None:
        anim = self.animator
        if anim is None:
            return
        self._leave_track()
        anim.set_jaw(float(degrees), anim.protrusion_mm)
        self._start()

    def set_gaze(self, yaw_deg: float, pitch_deg: float) -> None:
        """Turn the eyes (degrees: yaw toward the subject's left, pitch up); drawn at once."""
        anim = self.animator
        if anim is None:
            return
        self._leave_track()
        anim.set_gaze(float(yaw_deg), float(pitch_deg))
        self._move_inner()
        self.scene.request_render()

    def set_lids(self, closure: float) -> None:
        """Lid closure 0 (open) .. 1 (closed); the timer carries the lids there."""
        anim = self.animator
        if anim is None:
            return
        self._leave_track()
        anim.set_lids(float(closure))
        self._start()

    def relax(self) -> None:
        """All muscles relaxed, jaw closed, lids open, eyes ahead; the timer carries the
        face back to rest."""
        anim = self.animator
        if anim is None:
            return
        self._leave_track()
        anim.set_expression("neutral")
        anim.set_gaze(0.0, 0.0)
        self._preset = None
        self._show_state()
        self._move_inner()
        self._start()

    def contraction(self) -> dict[str, float]:
        """``{muscle code: contraction}`` the animator has now."""
        anim = self.animator
        if anim is None:
            return {}
        return {c: float(anim.contraction[i]) for i, c in enumerate(anim.muscle_codes)}

    def _show_state(self) -> None:
        anim = self.animator
        if anim is not None:
            self.panel.show_state(self.contraction(), anim.jaw_deg, anim.gaze, anim.lids)

    # ------------------------------------------------------------ running
    @property
    def running(self) -> bool:
        return self.timer.isActive()

    def _start(self) -> None:
        self._quiet_frames = 0
        if not self.timer.isActive():
            self.timer.start()
        self.panel.show_status("Moving …")

    def tick(self) -> None:
        """One frame: step the skin, move the drawn points, stop when settled."""
        anim = self.animator
        if anim is None or self.scene.closed:
            self.timer.stop()
            return
        t0 = time.perf_counter()
        anim.step(STEPS_PER_FRAME)
        # a live frame: the filtered skin without the exact (slow) inside-bone test; at rest
        # (settle_now, the final frame) the exact one is drawn
        points = anim.skin(exact=False).vertices
        before = self._points
        self.last_move_mm = (
            float(np.abs(points - before).max()) if before is not None else float("inf")
        )
        self._move_skin(points)
        self._move_inner_if_moved()
        self.scene.request_render()
        self.frame_ms.append(1000.0 * (time.perf_counter() - t0))
        del self.frame_ms[:-200]
        self._quiet_frames = self._quiet_frames + 1 if self.last_move_mm < SETTLED_MM else 0
        if self._quiet_frames >= SETTLED_FRAMES:
            self.timer.stop()
            self._move_skin(anim.skin().vertices)
            self.scene.request_render()
            ms = np.median(self.frame_ms[-50:])
            self.panel.show_status(
                f"At rest ({STEPS_PER_FRAME} steps a frame, {ms:.0f} ms median frame)."
            )
            self.settled.emit()

    def settle_now(self) -> int:
        """Run the skin to rest at once (the service's ``settle``; blocks ~1-3 s); returns steps."""
        anim = self.animator
        if anim is None:
            return 0
        self.timer.stop()
        steps = anim.settle()
        self._move_skin(anim.skin().vertices)
        self._move_inner()
        self.scene.request_render()
        self.panel.show_status(f"At rest ({steps} steps).")
        self.settled.emit()
        return steps

    def displacement(self) -> np.ndarray:
        """``(n,)`` distance (mm) of each skin vertex from its rest position."""
        anim = self.animator
        if anim is None:
            return np.zeros(0)
        return np.linalg.norm(anim.skin().vertices - anim.head.skin.vertices, axis=1)

    # ------------------------------------------------------------ timeline
    def open_track(self, path: str | Path) -> bool:
        """Load a track file onto the timeline (frame 0 shown); False (and a message in the
        dock) when the file is not a valid track."""
        from workbench.services.animation.track import load_track

        try:
            track = load_track(path)
        except WorkbenchError as exc:
            self.panel.show_track_message(str(exc))
            self.host.status(f"Track not opened: {exc}")
            return False
        self.panel.show_track_message("")
        self.set_track(track, Path(path))
        return True

    def set_track(self, track: Track, path: Path | None = None) -> None:
        """Put ``track`` on the timeline (``path``: the file it was read from, or None) and
        show its first frame; every checkpoint of an earlier track is dropped."""
        self.pause()
        self.track, self.track_path = track, path
        self._saved_as = None
        self.frames = None
        self._checkpoints.clear()
        self._target = None
        self.frame = None
        self.position = 0
        self._show_track_label()
        self.panel.show_length(track.duration)
        anim = self.animator
        if anim is None:  # frames need the head's muscle order: evaluated when it is loaded
            self.panel.show_timeline(track.n_frames, 0, track.fps, playing=False)
            return
        from workbench.services.animation.track import evaluate_track

        self.frames = evaluate_track(track, anim.muscle_codes)
        self._stride = max(
            1, math.ceil(self.frames.n_frames * 2 * anim.sim.x.nbytes / CHECKPOINT_BUDGET_BYTES)
        )
        self.seek(0)

    def _replace_track(self, track: Track) -> None:
        """An edited track: checkpoints before the first frame whose pose changed are kept."""
        from workbench.services.animation.track import evaluate_track

        anim, old = self.animator, self.frames
        self.track = track
        self._show_track_label()
        self.panel.show_length(track.duration)
        if anim is None:
            return
        new = evaluate_track(track, anim.muscle_codes)
        first = 0
        if old is not None:
            n = min(old.n_frames, new.n_frames)
            same = np.ones(n, bool)
            for name in ("contraction", "protrusion", "jaw_deg", "gaze", "lids"):
                a, b = getattr(old, name)[:n], getattr(new, name)[:n]
                same &= np.all(np.isclose(a, b, rtol=0, atol=1e-12).reshape(n, -1), axis=1)
            first = int(np.argmin(same)) if not same.all() else n
        self.frames = new
        self._checkpoints = {k: v for k, v in self._checkpoints.items() if k < first}
        if self.frame is not None and self.frame >= first:
            self.frame = None
        self.position = min(self.position, new.n_frames - 1)
        self._show_timeline()

    def _show_track_label(self) -> None:
        track = self.track
        if track is None:
            self.panel.show_track("No track: open one, or record keyframes.")
            return
        shown = self._saved_as or self.track_path
        name = shown.name if shown is not None else "new track (not saved)"
        self.panel.show_track(
            f"{name}: {track.duration:.2f} s at {track.fps:g} fps, {len(track.keys)} keys, "
            f"{len(track.phonemes)} phonemes"
        )

    def _show_timeline(self) -> None:
        track = self.track
        if track is None:
            self.panel.show_timeline(0, 0, 1.0, playing=False)
            return
        n = self.frames.n_frames if self.frames is not None else track.n_frames
        computing = self._target if self._target is not None and not self.playing else None
        self.panel.show_timeline(n, self.position, track.fps, computing_to=computing)

    @property
    def time_s(self) -> float:
        """The timeline's time (seconds)."""
        return self.position / self.track.fps if self.track is not None else 0.0

    def seek(self, frame: int) -> None:
        """Show track frame ``frame`` (see the module docstring: the same state as
        ``run_track`` there); a frame not computed yet is simulated toward, tick by tick."""
        frames = self.frames
        if frames is None or self.animator is None:
            return
        self.timer.stop()
        frame = int(np.clip(frame, 0, frames.n_frames - 1))
        self.position = frame
        self._target = frame
        self._show_timeline()
        if not self.track_timer.isActive():
            self.track_timer.setInterval(0)
            self.track_timer.start()

    def show_frame_now(self, frame: int) -> None:
        """:meth:`seek` and run the ticks until the frame is there (blocks; scripts, tests)."""
        self.seek(frame)
        while self._target is not None and self.frames is not None:
            self._track_tick()

    def play(self) -> None:
        """Play from the timeline's frame at the track's fps (from 0 when at the end)."""
        frames, track = self.frames, self.track
        if frames is None or track is None or self.animator is None:
            self.panel.show_timeline(0, 0, 1.0, playing=False)
            return
        self.timer.stop()
        if self.position >= frames.n_frames - 1 and self.frame == self.position:
            self.position = 0
            self._target = 0
        elif self.frame != self.position:
            self._target = self.position  # first get to the shown frame
        self.playing = True
        self.play_ms.clear()
        self.play_interval_ms.clear()
        self._last_tick = None
        self.panel.show_timeline(frames.n_frames, self.position, track.fps, playing=True)
        self.track_timer.setInterval(round(1000.0 / track.fps))
        self.track_timer.start()

    def pause(self) -> None:
        """Stop playing; the frame reached stays (drawn with the exact skin)."""
        was = self.playing
        self.playing = False
        if self.track is not None:
            self.panel.show_timeline(
                self.frames.n_frames if self.frames is not None else self.track.n_frames,
                self.position,
                self.track.fps,
                playing=False,
            )
        if was:
            self._report_play()
        if was and self._target is None:
            self.track_timer.stop()
            self._at_frame()

    def set_loop(self, on: bool) -> None:
        self.loop = bool(on)

    def set_length(self, seconds: float) -> None:
        """The track's duration (seconds); with no track, a new neutral track of that length."""
        from workbench.services.animation.track_edit import new_track, with_duration

        try:
            if self.track is None:
                self.set_track(new_track(seconds))
            elif abs(seconds - self.track.duration) > 1e-9:
                self._replace_track(with_duration(self.track, seconds))
        except WorkbenchError as exc:
            self.panel.show_track_message(str(exc))

    def _leave_track(self) -> None:
        """A slider or preset changed the pose: stop playing; the skin is off the track."""
        if self.playing:
            self.pause()
        self.track_timer.stop()
        self._target = None
        self.frame = None

    def _track_tick(self) -> None:
        """One timeline tick: one frame nearer the target (restore or simulate), drawn."""
        anim, frames = self.animator, self.frames
        if anim is None or frames is None or self.scene.closed:
            self.track_timer.stop()
            self.playing = False
            return
        t0 = time.perf_counter()
        if self._target is None:
            if not self.playing:
                self.track_timer.stop()
                return
            nxt = self.position + 1
            if nxt >= frames.n_frames:
                if not self.loop:
                    self.pause()
                    return
                nxt = 0
            self._target = nxt
        target = self._target
        self._one_toward(target)
        self.position = self.frame if self.frame is not None else self.position
        points = anim.skin(exact=False).vertices
        self._move_skin(points)
        self._move_inner_if_moved()
        self.scene.request_render()
        if self.frame == target:
            self._target = None
        if self.playing:
            self.play_ms.append(1000.0 * (time.perf_counter() - t0))
            del self.play_ms[:-500]
            if self._last_tick is not None:
                self.play_interval_ms.append(1000.0 * (t0 - self._last_tick))
                del self.play_interval_ms[:-500]
            self._last_tick = t0
            fps = self.track.fps if self.track is not None else 30.0
            self.track_timer.setInterval(0 if self._target is not None else round(1000.0 / fps))
            self._show_state()
            self._show_timeline()
            if len(self.play_ms) % 15 == 0:
                self._report_play()
        elif self._target is None:
            self.track_timer.stop()
            self._at_frame()
        else:
            self._show_timeline()

    def _report_play(self) -> None:
        """The median frame times in the dock and the status line (while and after playing)."""
        if not self.play_ms or self.track is None:
            return
        ms = float(np.median(self.play_ms))
        budget = 1000.0 / self.track.fps
        every = float(np.median(self.play_interval_ms)) if self.play_interval_ms else ms
        text = (
            f"{'Playing' if self.playing else 'Played'}: {ms:.0f} ms median frame, a frame every {every:.0f} ms with drawing "
            f"({len(self.play_ms)} frames; {min(1.0, budget / max(every, 1e-9)):.0%} of "
            f"real time at {self.track.fps:g} fps)."
        )
        self.panel.show_status(text)
        self.host.status(f"Animate: {text}")

    def _at_frame(self) -> None:
        """Stopped on a track frame: the exact skin, sliders and timeline shown (while the
        timeline's slider is being dragged the quick skin; the exact one on release)."""
        anim = self.animator
        if anim is None:
            return
        self._move_skin(anim.skin(exact=not self.panel.frame.isSliderDown()).vertices)
        self._move_inner()
        self._show_state()
        self._show_timeline()
        self.scene.request_render()
        if self.frame is not None:
            self.frame_shown.emit(self.frame)

    def _scrub_released(self) -> None:
        if not self.playing and self._target is None and self.frame == self.position:
            self._at_frame()

    def _one_toward(self, target: int) -> None:
        """Restore ``target``'s checkpoint, or the nearest earlier one, or simulate a frame."""
        if self.frame == target:
            return
        if target in self._checkpoints:
            self._restore(target)
            return
        below = max((k for k in self._checkpoints if k < target), default=None)
        if (
            self.frame is not None
            and self.frame < target
            and (below is None or self.frame >= below)
        ):
            self._simulate(self.frame + 1)
        elif below is not None:
            self._restore(below)
        else:
            self._simulate(0)

    def _simulate(self, i: int) -> None:
        """Frame ``i`` from frame ``i - 1``'s state, as ``play_track`` does (0: from rest)."""
        from workbench.services.animation.track import apply_frame, steps_per_frame

        anim, frames, track = self.animator, self.frames, self.track
        assert anim is not None and frames is not None and track is not None
        apply_frame(anim, frames, i)
        if i == 0:
            anim.sim.reset()  # run_track starts a fresh head: the rest skin
            anim.settle()
        else:
            anim.step(steps_per_frame(anim, track.fps))
        self.frame = i
        if i % self._stride == 0:
            self._checkpoints[i] = (anim.sim.x.copy(), anim.sim.v.copy())

    def _restore(self, i: int) -> None:
        from workbench.services.animation.track import apply_frame

        anim, frames = self.animator, self.frames
        assert anim is not None and frames is not None
        x, v = self._checkpoints[i]
        apply_frame(anim, frames, i)
        anim.update_muscles()  # targets and jaw anchors of frame i (moves only kinematic nodes)
        anim.sim.x = x.copy()
        anim.sim.v = v.copy()
        self.frame = i

    def computed_frames(self) -> list[int]:
        """Frames with a checkpoint (scrubbing there is instant)."""
        return sorted(self._checkpoints)

    # ------------------------------------------------------------ authoring
    def current_key(self) -> Key:
        """The animator's pose as a key at the timeline's time (all 24 contractions, jaw,
        gaze, lids; lip protrusion only through the last preset, when it is the preset's)."""
        from workbench.services.animation.animator import EXPRESSIONS
        from workbench.services.animation.track import Key

        anim = self.animator
        assert anim is not None
        expressions: dict[str, float] = {}
        if np.any(anim.protrusion != 0) and self._preset is not None:
            name, w = self._preset
            e = EXPRESSIONS[name]
            want = np.array(
                [np.clip(w * e.protrusion.get(c, 0.0), -1, 1) for c in anim.muscle_codes]
            )
            if np.allclose(want, anim.protrusion, atol=1e-9):
                expressions = {name: w}
        return Key(
            round(self.time_s, 6),
            expressions,
            {c: round(float(anim.contraction[i]), 4) for i, c in enumerate(anim.muscle_codes)},
            round(float(anim.jaw_deg), 4),
            (round(anim.gaze[0], 4), round(anim.gaze[1], 4)),
            round(float(anim.lids), 4),
        )

    def record_key(self) -> Key | None:
        """Add the current pose as a key at the timeline's time (a new track if none)."""
        from workbench.services.animation.track_edit import new_track, with_key

        if self.animator is None:
            return None
        try:
            track = self.track
            if track is None:
                track = new_track(NEW_TRACK_S)
                self.set_track(track)
                self._leave_track()  # keep the slider pose on screen
            key = self.current_key()
            track = with_key(track, key)
        except WorkbenchError as exc:
            self.panel.show_track_message(str(exc))
            return None
        self.panel.show_track_message("")
        self._replace_track(track)
        dropped = (
            ""
            if key.expressions or not np.any(self.animator.protrusion != 0)
            else " (lip protrusion not kept: a key has it only through a preset)"
        )
        self.panel.show_status(f"Key recorded at {key.t:.2f} s{dropped}.")
        return key

    def save_track_to(self, path: str | Path, *, force: bool = False) -> Path | None:
        """Write the timeline's track as JSON (atomic; never over the file it came from)."""
        from workbench.services.animation.track_edit import save_track

        if self.track is None:
            return None
        try:
            out = save_track(self.track, path, [self.track_path], force=force)
        except WorkbenchError as exc:
            self.panel.show_track_message(str(exc))
            return None
        self.panel.show_track_message("")
        self._saved_as = Path(out)
        self._show_track_label()
        self.panel.show_status(f"Track saved: {out}")
        return out

    def _ask_open_track(self) -> None:
        from PySide6.QtWidgets import QFileDialog

        path, _ = QFileDialog.getOpenFileName(
            self.host.window(), "Open a keyframe track", "", "Tracks (*.json);;All files (*)"
        )
        if path:
            self.open_track(path)

    def _ask_save_track(self) -> None:
        from PySide6.QtWidgets import QFileDialog

        path, _ = QFileDialog.getSaveFileName(
            self.host.window(), "Save the track", "", "Tracks (*.json)"
        )
        if path:  # the dialog asked before replacing a file; it is kept as a backup
            self.save_track_to(path, force=True)

    def detach(self) -> None:
        """Stop the timers (before the view closes)."""
        self.timer.stop()
        self.track_timer.stop()
        self.playing = False
