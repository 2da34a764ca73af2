"""Eyeballs of the reference head: 24 mm globes with a corneal bulge, placed in the orbits.

Units and frame: millimetres, head frame (x to the subject's left, y up,
z forward; Frankfort Horizontal y = 0).

Globe: a sphere of radius 12 mm (axial length about 24 mm in adults,
Bekerman et al. 2014) whose front carries the cornea: a spherical cap of
radius 7.8 mm meeting the globe at the limbus (corneal diameter 11.7 mm), so
the corneal apex stands about 1.1 mm proud of the sclera sphere.  The
cornea's outline (the limbus) doubles as the iris ring in renders.

Placement (done in :func:`workbench.core.headgen.skull.build_skull`): the globe
is centred on the orbital opening horizontally and vertically (the
traditional guideline, e.g. Taylor 2001) and looks straight ahead (+z).
Its projection: Stephan (2002) showed that the traditional rule -- corneal
apex on the tangent from the mid-supraorbital to the mid-infraorbital
margin -- under-predicts globe projection by about 4 mm on average, so the
apex is put 4 mm in front of that tangent.  On the reference skull this is
about 11 mm in front of ectoconchion (lateral orbital rim), inside the
8-12 mm usually quoted for the lateral-rim rule; the value is reported in
``SkullTemplate.parameters["corneal_apex_anterior_to_ec_mm"]``.
"""

from __future__ import annotations

import numpy as np

from workbench.core.mesh import Mesh


def icosphere(subdivisions: int = 4) -> Mesh:
    """Unit icosphere (outward winding), ``20 * 4**subdivisions`` triangles."""
    t = (1.0 + 5**0.5) / 2.0
    v = np.array(
        [
            [-1, t, 0],
            [1, t, 0],
            [-1, -t, 0],
            [1, -t, 0],
            [0, -1, t],
            [0, 1, t],
            [0, -1, -t],
            [0, 1, -t],
            [t, 0, -1],
            [t, 0, 1],
            [-t, 0, -1],
            [-t, 0, 1],
        ],
        float,
    )
    f = np.array(
        [
            [0, 11, 5],
            [0, 5, 1],
            [0, 1, 7],
            [0, 7, 10],
            [0, 10, 11],
            [1, 5, 9],
            [5, 11, 4],
            [11, 10, 2],
            [10, 7, 6],
            [7, 1, 8],
            [3, 9, 4],
            [3, 4, 2],
            [3, 2, 6],
            [3, 6, 8],
            [3, 8, 9],
            [4, 9, 5],
            [2, 4, 11],
            [6, 2, 10],
            [8, 6, 7],
            [9, 8, 1],
        ],
        np.int64,
    )
    v /= np.linalg.norm(v, axis=1, keepdims=True)
    for _ in range(subdivisions):
        edges = np.sort(np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]]), axis=1)
        uniq, inv = np.unique(edges, axis=0, return_inverse=True)
        mid = v[uniq].mean(axis=1)
        mid /= np.linalg.norm(mid, axis=1, keepdims=True)
        m = len(f)
        a, b, c = (len(v) + inv.ravel()[k * m : (k + 1) * m] for k in range(3))
        v = np.vstack([v, mid])
        f = np.concatenate(
            [
                np.column_stack([f[:, 0], a, c]),
                np.column_stack([a, f[:, 1], b]),
                np.column_stack([c, b, f[:, 2]]),
                np.column_stack([a, b, c]),
            ]
        )
    return Mesh(v, f)


def eyeball_mesh(
    centre,
    radius: float = 12.0,
    axis=(0.0, 0.0, 1.0),
    cornea_radius: float = 7.8,
    limbus_radius: float = 5.85,
    subdivisions: int = 4,
) -> Mesh:
    """One globe (mm): sphere of ``radius`` with a corneal cap bulging along ``axis``."""
    unit = icosphere(subdivisions)
    d = unit.vertices
    ax = np.asarray(axis, float) / np.linalg.norm(axis)
    # corneal sphere through the limbus circle, centre on the optical axis
    limbus_depth = np.sqrt(radius**2 - limbus_radius**2)
    c_off = limbus_depth - np.sqrt(cornea_radius**2 - limbus_radius**2)
    cos_t = d @ ax
    # distance along direction d to the corneal sphere (centre c_off * ax): r² - 2 r c cos + c² = R²
    disc = np.maximum(cornea_radius**2 - c_off**2 * (1.0 - cos_t**2), 0.0)
    r_cornea = c_off * cos_t + np.sqrt(disc)
    r = np.where(cos_t * radius > limbus_depth - 1e-9, np.maximum(radius, r_cornea), radius)
    return Mesh(np.asarray(centre, float) + d * r[:, None], unit.faces)


def corneal_apex_offset(
    radius: float = 12.0, cornea_radius: float = 7.8, limbus_radius: float = 5.85
) -> float:
    """Distance (mm) from the globe centre to the corneal apex."""
    limbus_depth = np.sqrt(radius**2 - limbus_radius**2)
    return float(limbus_depth - np.sqrt(cornea_radius**2 - limbus_radius**2) + cornea_radius)
