"""Which separate pieces of a bone mesh are not bone: CT tables, head holders (issue 28).

Units mm.  A bone surface exported with every piece (or every piece over
5 %) carries the mandible, vertebrae and debris, and also whatever else was
dense enough at the iso level: the scanner's table, a head holder or
cradle.  Those are man-made and look it: a table is a flat plate, a holder a
smooth shell, and both are of one thickness all over.  Bone is not: the
vault's tables and diploe, the thin orbital and sinus walls, the thick skull
base and the mandible's cortex give a spread of thicknesses.

For every connected piece holding at least :data:`MIN_SHARE` of the surface,
area-weighted samples cast a ray straight inward (against the outward
normal) to the piece's other side:

* **uniform**: the share of samples whose thickness lies within
  :data:`UNIFORM_MM` of the piece's median thickness.  On the robustness
  corpus (headsq and both Visible Human CTs, 250–700 HU and multi-Otsu):
  tables 0.95–0.98, head holders 0.95–0.97 (one on headsq's 3.2 mm voxels at
  its multi-Otsu level: 0.87); crania 0.22–0.73, detached mandibles 0.41–0.74
  (the highest at 700 HU, where only the cortex is left);
* **planar**: the share whose normal lies within 15° of the piece's main
  normal axis (tables 0.95–0.97; bone pieces 0.04–0.14).

A piece is apparatus when it is uniform (≥ :data:`UNIFORM_APPARATUS`) or
planar (≥ :data:`PLANAR_APPARATUS`) — but the most bone-like large piece
(the least uniform among those over :data:`MAIN_SHARE`) is always kept, so
a skull can never be thrown out as its own apparatus.  Deterministic
(seeded samples).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from workbench.core.mesh import Mesh

#: pieces smaller than this share of the surface are not judged (debris, a hyoid)
MIN_SHARE = 0.01
#: thickness within this of the piece's median counts as "the same thickness" (mm)
UNIFORM_MM = 1.5
#: rays longer than this did not find the piece's other side (mm)
MAX_THICKNESS_MM = 60.0
#: between the bone's highest (0.74) and the apparatus's lowest (0.87)
UNIFORM_APPARATUS = 0.85
PLANAR_APPARATUS = 0.85
#: candidates for "the skull" (always kept): pieces over this share of the surface
MAIN_SHARE = 0.1
SAMPLES = 1500


@dataclass(frozen=True)
class Piece:
    """One connected piece of a bone mesh and how it was judged.

    Attributes
    ----------
    faces : (k,) int
        Its face indices in the mesh.
    share : float
        Its share of the mesh's area.
    uniform, planar : float
        See the module docstring.
    thickness_mm : float
        Median inward thickness (NaN when no ray found the other side).
    extent_mm : (3,)
        Sorted extents of its bounding box (mm).
    apparatus : bool
    """

    faces: np.ndarray
    share: float
    uniform: float
    planar: float
    thickness_mm: float
    extent_mm: np.ndarray
    apparatus: bool

    def describe(self) -> str:
        """The piece in words, for a note to the user."""
        size = " × ".join(f"{e:.0f}" for e in self.extent_mm[::-1][:2])
        if self.planar >= PLANAR_APPARATUS:
            kind = "a flat plate (a CT table?)"
        else:
            kind = f"a shell of one thickness, {self.thickness_mm:.1f} mm (a head holder?)"
        return f"{kind}, {size} mm, {100 * self.share:.0f} % of the surface"


def _sub_mesh(mesh: Mesh, faces: np.ndarray) -> Mesh:
    f = mesh.faces[faces]
    used = np.unique(f)
    remap = np.full(mesh.n_vertices, -1, np.int64)
    remap[used] = np.arange(len(used))
    return Mesh(mesh.vertices[used], remap[f])


def judge_pieces(mesh: Mesh, *, seed: int = 0) -> list[Piece]:
    """Every piece of ``mesh`` (mm) over :data:`MIN_SHARE` of its area, judged (largest first)."""
    from workbench.core.isosurface import face_component_labels
    from workbench.core.raycast import RayCaster
    from workbench.core.rigid_search import surface_samples

    labels = face_component_labels(mesh.faces, mesh.n_vertices)
    areas = np.bincount(labels, weights=mesh.face_areas)
    total = float(areas.sum())
    if total <= 0 or len(areas) < 2:
        return []
    order = [int(c) for c in np.argsort(areas)[::-1] if areas[c] >= MIN_SHARE * total]
    if len(order) < 2:
        return []
    pieces = []
    for c in order:
        faces = np.flatnonzero(labels == c)
        piece = _sub_mesh(mesh, faces).outward()
        s = surface_samples(piece, SAMPLES, np.random.default_rng(seed))
        n = s.normals
        _, vecs = np.linalg.eigh(n.T @ n)
        planar = float(np.mean(np.abs(n @ vecs[:, -1]) > np.cos(np.radians(15.0))))
        hits = RayCaster(piece).first_hits(s.points - 0.05 * n, -n)
        d = np.where(hits.hit, hits.distance, np.inf)
        found = np.isfinite(d) & (d < MAX_THICKNESS_MM)
        thick = float(np.median(d[found])) if found.any() else float("nan")
        uniform = float(np.mean(np.abs(d - thick) < UNIFORM_MM)) if found.any() else 0.0
        pieces.append(
            Piece(
                faces,
                float(areas[c] / total),
                uniform,
                planar,
                thick,
                np.sort(np.ptp(piece.vertices, axis=0)),
                uniform >= UNIFORM_APPARATUS or planar >= PLANAR_APPARATUS,
            )
        )
    main = [p for p in pieces if p.share >= MAIN_SHARE]
    if main:
        keep = min(main, key=lambda p: p.uniform)  # the most bone-like large piece
        pieces = [
            Piece(p.faces, p.share, p.uniform, p.planar, p.thickness_mm, p.extent_mm, False)
            if p is keep
            else p
            for p in pieces
        ]
    return pieces


def apparatus_faces(mesh: Mesh, pieces: list[Piece]) -> np.ndarray:
    """``(n_faces,)`` bool: the faces of the pieces judged apparatus."""
    out = np.zeros(mesh.n_faces, bool)
    for p in pieces:
        if p.apparatus:
            out[p.faces] = True
    return out
