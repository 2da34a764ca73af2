"""Checks of a reconstruction's settings before the registration, and of its face after.

Units mm.  Each raises :class:`~workbench.core.errors.InputError` naming the option (or
the result) and the problem; the bounds are those of :mod:`workbench.core.limits`.

- :func:`check_fit_settings`: the depth table and its group, the build and the ensemble
  size, the rule ids, the codes of overrides and exclusions;
- :func:`check_face_fits_skull`: the final sanity check of a fitted face.
"""

from __future__ import annotations

from typing import Any

from workbench.core.errors import InputError
from workbench.core.limits import MAX_ENSEMBLE, check_build_sd, check_count
from workbench.core.limits import check_face_fits_skull as _face_fits
from workbench.core.mesh import Mesh


def check_fit_settings(dowels: Any, *, ensemble: int = 0, rules: Any = ()) -> None:
    """The depth table (loaded and checked), its group for sex and build, the ensemble
    size, the published rule ids (``--rule``) and the landmark codes of the depth
    overrides and exclusions.

    ``dowels`` is a :class:`~workbench.model.reconstruction_setup.DowelSettings`.
    """
    if rules:
        from workbench.services.guides.rules import load_rules

        table_of_rules = load_rules()
        bad = [r for r in rules if r not in table_of_rules]
        if bad:
            known = sorted(table_of_rules)
            raise InputError(
                "--rule",
                f"unknown prediction rule(s): {', '.join(bad)}",
                f"known rules: {', '.join(known)}",
            )
    from workbench.io.tables import load_depth_table
    from workbench.services.tissue.dowels import (
        DepthSettings,
        build_score,
        choose_depth_group,
        setting_codes,
    )

    check_count(
        ensemble,
        "--ensemble",
        0,
        MAX_ENSEMBLE,
        why=f"the spread map settles by ~50 fits; more than {MAX_ENSEMBLE} only takes longer",
    )
    if not isinstance(dowels.build, str):
        check_build_sd(dowels.build)
    table = load_depth_table(dowels.table)  # refuses depths and SDs out of bounds
    _, _, by_model = build_score(table, dowels.build)  # refuses what the model cannot make
    choose_depth_group(table, None, dowels.sex, "normal" if by_model else dowels.build)
    # unknown codes in the overrides and exclusions, before the registration
    setting_codes(
        DepthSettings(overrides=dict(dowels.overrides), excluded=frozenset(dowels.excluded))
    )


def check_face_fits_skull(face: Mesh, skull: Mesh, source: str = "reconstruction") -> None:
    """Refuse a fitted face whose bounding box does not fit the skull's (same frame, mm).

    The bounds are :data:`~workbench.core.limits.FACE_TO_SKULL_EXTENT_RANGE`
    (see :func:`workbench.core.limits.check_face_fits_skull`).
    """
    _face_fits(face.extent, skull.extent, source)
