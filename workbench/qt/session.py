"""The window's derived results: the fit, the dowel preview, the true skin, the comparison.

A :class:`Session` only *stores* results and *signals* their changes; it
computes nothing.  The fit itself is the one pipeline,
:func:`workbench.services.reconstruction.case_steps.fit_face` (→ :mod:`workbench.services.reconstruction.service`),
run in the worker by the main window, which hands each result to the session
on the GUI thread.  Panels and views read the results here and follow the
signals, instead of reaching into the window.

None of this is part of the case (see :mod:`workbench.qt.document`): a case
keeps the settings that produce these results, and opening or replacing a
case clears them (:meth:`Session.clear_fit`).  Units mm, input frame (the
fit's head-frame parts are documented in :mod:`workbench.services.reconstruction.case_steps`).

Each setter emits its signal on every call, also when the value is the same:
a listener is told "this is the current value" (e.g. a panel cleared again
when a new case arrives).
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from PySide6.QtCore import QObject, Signal

if TYPE_CHECKING:
    from workbench.services.reconstruction.case_steps import DowelPreview, FitResult
    from workbench.services.validation.compare import Comparison


class Session(QObject):
    """See the module docstring.  Signals carry the new value (None: cleared)."""

    fit_changed = Signal(object)  # FitResult | None
    preview_changed = Signal(object)  # DowelPreview | None
    truth_changed = Signal(object)  # (name, mesh) | None
    comparison_changed = Signal(object)  # Comparison | None

    def __init__(self, parent: QObject | None = None) -> None:
        super().__init__(parent)
        self._fit: FitResult | None = None
        self._preview: DowelPreview | None = None
        self._truth: tuple[str, Any] | None = None
        self._comparison: Comparison | None = None
        #: the dense registration Suggest made: ``(skull mesh, orientation, sex, registration)``;
        #: the next Reconstruct of that skull reuses it (no second registration)
        self.suggested_registration: tuple[Any, Any, str, Any] | None = None

    # ------------------------------------------------------------ accessors
    @property
    def fit(self) -> FitResult | None:
        """The last fitted face (:class:`workbench.services.reconstruction.case_steps.FitResult`), or None."""
        return self._fit

    @property
    def preview(self) -> DowelPreview | None:
        """The last dowel plan drawn (:class:`workbench.services.reconstruction.case_steps.DowelPreview`), or None."""
        return self._preview

    @property
    def truth(self) -> tuple[str, Any] | None:
        """The loaded true skin as ``(file name, mesh)`` (mm, input frame), or None."""
        return self._truth

    @property
    def comparison(self) -> Comparison | None:
        """The last comparison of the fitted face with the true skin, or None."""
        return self._comparison

    # ------------------------------------------------------------ setters
    def set_fit(self, fit: FitResult | None) -> None:
        self._fit = fit
        self.fit_changed.emit(fit)

    def set_preview(self, preview: DowelPreview | None) -> None:
        self._preview = preview
        self.preview_changed.emit(preview)

    def set_truth(self, name: str, mesh: Any) -> None:
        self._truth = (name, mesh)
        self.truth_changed.emit(self._truth)

    def set_comparison(self, comparison: Comparison | None) -> None:
        self._comparison = comparison
        self.comparison_changed.emit(comparison)

    def clear_fit(self) -> None:
        """A new case: no fit and no dowel plan yet (the true skin stays loaded)."""
        self.set_fit(None)
        self.set_preview(None)
        self.suggested_registration = None
