"""The Appearance dock's tool: the case's chosen colours, as commands and on the face layer.

Edits in :class:`~workbench.qt.panels.appearance_panel.AppearancePanel` become
:class:`~workbench.commands.appearance.SetAppearance` commands on the one
undo stack (moves of one region's sliders merge into one step; a slider
being dragged only previews, its release pushes).  Undo, redo and a newly
opened case come back through the document's ``part_changed`` /
``case_replaced`` and set the panel and the face again.

The face layer is drawn by the Reconstruct tool (through
:meth:`~workbench.qt.scene.SceneView.show_face`); this tool colours the face
actor in place (:func:`workbench.render.visuals.face.paint_face`) whenever
the colours change and, through an observer of the view's render start,
whenever a new face actor appears (a fit, a reopened case, the colouring
combo set back to "skin").  A face coloured by a value (spread, band) is left
alone.  The colours are computed on the fitted head in its head frame
(:func:`workbench.services.appearance.skin_colours`), one per skin vertex;
the face drawn is that skin in the input frame, vertex for vertex.  While a
visible face shows them, the view's lower left corner says they are an
artistic choice (:data:`VIEW_NOTE`).

The hair, brows, beard and moustache the case chose are drawn on the
``hair`` layer over the face as it is shown (the build slider's build
included), grown once per head and style in a worker
(:func:`workbench.services.grooming.head_grooming`) and rebuilt on the drawn
skin :data:`HAIR_SETTLE_MS` after it stops moving.  For a light view every
:data:`VIEW_STRIDE`-th strand of the scalp hair is drawn; portraits and
exports draw them all.  They are artistic additions, not evidence (the dock
and the layer's name say so).

"Colour the face" is a view setting, not part of the case: whenever the
case's colours change (an edit, undo, redo, another case) it is ticked if the
case has colours and cleared if it has none; ticked by hand with no colours,
the face shows the default colouring.  The colours
are an artistic choice, not evidence; the dock says so.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np
from PySide6.QtCore import QObject, QTimer

from workbench.core.frame import apply_transform
from workbench.model.appearance import REGIONS, Appearance, Hsv
from workbench.qt.tools.common import HairGrower
from workbench.render.visuals.face import add_colour_note, face_painted, paint_face
from workbench.render.visuals.update import drawn_points, source_data
from workbench.services import appearance as colouring

if TYPE_CHECKING:
    from workbench.qt.document import Document
    from workbench.qt.panels.appearance_panel import AppearancePanel
    from workbench.qt.scene import SceneView
    from workbench.qt.session import Session

#: the caption in the 3D view while the face shows chosen colours
VIEW_NOTE = "Face colours: an artistic choice, not evidence"
#: the view draws every n-th strand of the scalp hair (a lighter scene)
VIEW_STRIDE = 2
#: the hair is rebuilt on a moved face once it has rested this long (ms)
HAIR_SETTLE_MS = 150


class AppearanceTool(QObject):
    """See the module docstring.

    Parameters
    ----------
    panel : AppearancePanel
    document : Document
        The window's case and undo stack.
    session : Session
        Holds the fit whose face is coloured.
    scene : SceneView
        The main view (its ``"face"`` layer).
    host : object
        The window: ``status(text)``.
    """

    def __init__(
        self,
        panel: AppearancePanel,
        document: Document,
        session: Session,
        scene: SceneView,
        host: Any,
        parent: QObject | None = None,
        runner: Any = None,
    ) -> None:
        super().__init__(parent)
        self.panel, self.document, self.session = panel, document, session
        self.scene, self.host, self.runner = scene, host, runner
        #: what the hair layer was drawn for: (face actor, its points' time, fit, look)
        self._hair_key: tuple[Any, ...] | None = None
        self._grower = HairGrower(
            runner,
            "hair",
            self.draw_hair,
            lambda exc: self.host.status(f"The hair could not be placed: {exc}"),
        )
        self._hair_timer = QTimer(self)
        self._hair_timer.setSingleShot(True)
        self._hair_timer.setInterval(HAIR_SETTLE_MS)
        self._hair_timer.timeout.connect(self.draw_hair)
        #: the colours previewed while a slider is dragged (not in the case yet)
        self.preview: Appearance | None = None
        self._weights: tuple[Any, dict[str, np.ndarray]] | None = None
        self._colours: tuple[Any, Appearance | None, np.ndarray] | None = None
        self._painted: tuple[Any, Any, Appearance | None, bool] | None = None
        panel.shown_toggled.connect(self.set_shown)
        panel.tone_chosen.connect(self.set_tone)
        panel.iris_chosen.connect(self.set_iris)
        panel.colour_changed.connect(self.set_colour)
        panel.follow_requested.connect(lambda region: self.set_colour(region, None, True))
        panel.remove_requested.connect(self.remove)
        panel.style_chosen.connect(self.set_style)
        document.case_replaced.connect(self._case_replaced)
        document.part_changed.connect(self._part_changed)
        session.fit_changed.connect(lambda _fit: self.paint())
        #: the view's caption while the face shows the colours
        self.note = add_colour_note(scene.plotter, VIEW_NOTE)
        window = getattr(scene.plotter, "render_window", None)
        self._observer = None if window is None else window.AddObserver("StartEvent", self._check)
        self._show_panel()

    # ------------------------------------------------------------ what is shown
    @property
    def shown(self) -> bool:
        """ "Colour the face" is ticked."""
        return self.panel.shown.isChecked()

    def appearance(self) -> Appearance | None:
        """The colours shown: the dragged preview, else the case's."""
        return self.preview if self.preview is not None else self.document.case.appearance

    def colours(self) -> np.ndarray | None:
        """``(n_skin, 3)`` uint8 sRGB of the fitted face's vertices, or None (no fit)."""
        fit = self.session.fit
        if fit is None:
            return None
        head, look = fit.recon.head, self.appearance()
        if self._colours is not None and self._colours[0] is head and self._colours[1] == look:
            return self._colours[2]
        if self._weights is None or self._weights[0] is not head:
            self._weights = (head, colouring.region_weights(head))
        rgb = colouring.skin_colours(head, look, self._weights[1])
        self._colours = (head, look, rgb)
        return rgb

    def paint(self, render: bool = True) -> bool:
        """Colour the face layer as the dock says (plain when not shown); True if it shows
        the chosen colours.  ``render=False``: ask for no render (one is under way)."""
        actors = self.scene.actors("face")
        if not actors:
            self._painted = None
            return False
        actor, look, on = actors[0], self.appearance(), self.shown
        rgb = self.colours() if on else None
        if rgb is None and face_painted(actor):
            paint_face(actor, None)
        elif rgb is not None:
            paint_face(actor, rgb)
        self._painted = (actor, self.session.fit, look, on)
        if render:
            self.scene.request_render()
        return face_painted(actor)

    def _check(self, *_args: Any) -> None:
        """Before each render: a face drawn anew (or a change not painted yet) is painted,
        and the view's note shows while a visible face shows the chosen colours."""
        actors = self.scene.actors("face")
        done = self._painted
        if actors and not (
            done is not None
            and done[0] is actors[0]
            and done[1] is self.session.fit
            and done[2] == self.appearance()
            and done[3] == self.shown
        ):
            self.paint(render=False)
        on = bool(actors) and face_painted(actors[0]) and bool(actors[0].GetVisibility())
        if bool(self.note.GetVisibility()) != on:
            self.note.SetVisibility(on)
        if self._hair_wanted() != self._hair_key and not self._hair_timer.isActive():
            self._hair_timer.start()

    # ------------------------------------------------------------ hair
    def _hair_wanted(self) -> tuple[Any, ...] | None:
        """What the hair layer should be drawn for now (None: nothing to draw)."""
        actors = self.scene.actors("face")
        look, fit = self.appearance(), self.session.fit
        if not actors or fit is None or look is None or not look.grooming:
            return None
        points = source_data(actors[0]).GetPoints()
        hair_look = (look.grooming, look.colour("hair"), look.colour("brows"), look.tone)
        return (actors[0], points.GetMTime() if points is not None else 0, fit, hair_look)

    def draw_hair(self) -> None:
        """Draw the chosen hair on the face as shown (grown in a worker the first time)."""
        from workbench.services.grooming import hair_meshes

        wanted = self._hair_wanted()
        if wanted is None:
            if self.scene.has("hair"):
                self.scene.show_hair([])
            self._hair_key = None
            return
        fit, look = self.session.fit, self.appearance()
        assert fit is not None and look is not None
        head = fit.recon.head
        if not self._grower.ready(head, look):
            return
        recon = fit.recon
        shown = drawn_points(source_data(self.scene.actors("face")[0]))
        skin = apply_transform(recon.input_to_head, shown)
        rotation = np.linalg.inv(recon.input_to_head)[:3, :3]
        pieces = [
            (recon.mesh_to_input(hair.mesh), hair.srgb, hair.normals @ rotation.T)
            for hair in hair_meshes(head, look, skin, stride=VIEW_STRIDE)
        ]
        self.scene.show_hair(pieces)
        self._hair_key = wanted

    def _show_panel(self) -> None:
        look = self.appearance()
        colours = {r: colouring.region_colour(look, r) for r in REGIONS}
        self.panel.show_colours(
            look, colours, {r: colouring.hsv_srgb(c) for r, c in colours.items()}
        )

    # ------------------------------------------------------------ edits
    def case_open(self) -> bool:
        """A case is open (a skull or a case file) to keep the colours in."""
        doc = self.document
        return doc.path is not None or doc.has_specimen

    def _push(self, new: Appearance | None, merge_key: str = "") -> bool:
        from workbench.commands.appearance import SetAppearance

        self.preview = None
        if not self.case_open():
            self.host.status("Open a case first: the colours are kept in a case.")
            self._show_panel()
            return False
        if new == self.document.case.appearance:
            self._show_panel()
            self.paint()
            return False
        if not self.document.push(SetAppearance(new, merge_key=merge_key)):
            self._show_panel()
            return False
        return True

    def _current(self) -> Appearance:
        return self.document.case.appearance or Appearance()

    def set_tone(self, tone: str) -> bool:
        """Paint the skin with preset ``tone`` (a base set by hand is dropped)."""
        return self._push(self._current().with_tone(tone))

    def set_iris(self, iris: str) -> bool:
        return self._push(self._current().replaced(iris=iris))

    def set_colour(self, region: str, colour: Hsv | None, final: bool = True) -> bool:
        """``region`` in ``colour`` (None: follow the base again); ``final=False`` only
        previews it (a slider being dragged)."""
        new = self._current().with_colour(region, colour)
        if not final:
            self.preview = new
            self.panel.set_shown(True)
            self._show_panel()
            self.paint()
            return True
        return self._push(new, merge_key=region if colour is not None else "")

    def set_style(self, kind: str, style: str) -> bool:
        """Choose ``style`` (``"none"``: nothing) for ``kind`` (hair, brows, beard, moustache)."""
        return self._push(self._current().with_style(kind, style))

    def remove(self) -> bool:
        """The case keeps no colours (the face is drawn plain)."""
        return self._push(None)

    def set_shown(self, on: bool) -> None:
        """ "Colour the face" (a view setting): the face in its colours or plain."""
        self.panel.set_shown(on)
        if not self.paint() and on and self.scene.has("face") and self.session.fit is not None:
            self.host.status(
                "The face is coloured by a value (Reconstruct dock): choose the skin colouring "
                "there to see the chosen colours."
            )

    # ------------------------------------------------------------ the case
    def _case_replaced(self) -> None:
        self.preview = None
        self._colours = None
        self.panel.set_shown(self.document.case.appearance is not None)
        self._show_panel()
        self.panel.show_status(
            "The case keeps chosen colours." if self.document.case.appearance else ""
        )
        self.paint()

    def _part_changed(self, part: str) -> None:
        if part != "appearance":
            return
        self.preview = None
        look = self.document.case.appearance
        self.panel.set_shown(look is not None)  # changed colours are shown; none: plain
        self._show_panel()
        self.panel.show_status(
            f"Kept in the case (undo: Ctrl+Z): {colouring.colour_summary(look)}"
            if look is not None
            else "The case keeps no colours."
        )
        self.paint()

    def detach(self) -> None:
        """Remove the render observer (the window closes)."""
        window = getattr(self.scene.plotter, "render_window", None)
        if self._observer is not None and window is not None:
            window.RemoveObserver(self._observer)
        self._observer = None
