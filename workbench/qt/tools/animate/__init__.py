"""The "Animate" tool: a reference head's face moved live in the 3D view.

The physics is the service's (:class:`workbench.services.animation.animator.Animator`,
``workbench animate``); this tool only sets its parameters from the
:class:`~workbench.qt.panels.animate_panel.AnimatePanel` and shows the
result.  The head is loaded in the window's worker (the reference head from
the template cache, then the animator's set-up, ~1.5 s); afterwards a
:class:`QTimer` every :data:`FRAME_MS` ms advances the skin
:data:`STEPS_PER_FRAME` simulation steps on the GUI thread (~600 steps/s for
the reference skin: ~17 ms a frame) and moves the drawn skin's points in
place (no actor is re-added).  The timer stops once the skin has settled
(largest vertex move in a frame below :data:`SETTLED_MM` for
:data:`SETTLED_FRAMES` frames) and starts again with the next change.

Frames and units: mm, the head's own frame (the reference head is stored in
the Frankfort head frame: x to the subject's left, y up, z toward the face),
not the case's skull.  Its layers (skin; skull, teeth and eyes) belong to
this tool, not to :data:`workbench.qt.scene.LAYERS`.

Undo: slider and preset changes are view state, not case edits.  The case
is not changed, nothing goes on the document's undo stack, and Relax is the
way back to the face at rest.

Gaze and lids: the gaze sliders turn the eyes (drawn from the animator's
pose of the eyes, as :meth:`Animator.meshes` gives it; the skin does not
depend on the gaze, so nothing is simulated), the lid slider sets the lid
nodes' targets and the timer carries the lids there.

Timeline (a track: :mod:`workbench.services.animation.track`).  Frame ``i``
of a track means exactly what :func:`~workbench.services.animation.track.run_track`
computes: frame 0 is the rest skin settled in frame 0's pose, every later
frame is frame ``i``'s pose (``apply_frame``) and ``steps_per_frame`` steps
(20 steps of 1/600 s at 30 fps) from frame ``i - 1``'s simulated state, so
the skin keeps its own dynamics (lag, overshoot) between keys.  Play runs
that, one frame per tick of a :class:`QTimer` at the track's fps (slower
than real time when a frame takes longer to compute than ``1 / fps``; no
frame is skipped, since each one's state is the next one's start).

Scrubbing semantics, chosen so that a scrubbed frame is the same skin as
``run_track``'s (not a quasi-static approximation): the simulation state
(node positions and velocities) of every computed frame is kept as a
checkpoint (every ``stride``-th frame once a track's checkpoints would pass
:data:`CHECKPOINT_BUDGET_BYTES`).  Scrubbing to a frame, backwards or
forwards, restores its checkpoint (instant); a frame not computed yet is
reached by simulating on from the nearest earlier checkpoint, one frame per
timer tick so the window stays responsive (the time label says so).
Resetting to a frame's pose and settling instead would be quicker on a long
jump but shows the face at rest in that pose, which differs from the
played frame wherever the face is moving (speech: millimetres).  A slider,
preset or Relax change leaves the track: the skin is then the slider pose
(moving under the live timer as before), and "Record keyframe" stores that
pose as a key at the timeline's time.

Modules: :mod:`~workbench.qt.tools.animate.tool` is the controller
(:class:`AnimateTool`: loading, parameters, the live timer, the timeline),
:mod:`~workbench.qt.tools.animate.drawing` its drawing (the skin and the
inner parts moved in place) and the worker's :func:`load_animator`.
"""
