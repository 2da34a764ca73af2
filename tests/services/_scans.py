"""Damaged scans made from a reference head's skin (head frame, mm) for the scan-fit tests."""

from __future__ import annotations

import numpy as np

from workbench.core.landmarks import LandmarkSet
from workbench.core.mesh import Mesh, concatenate
from workbench.model.template import TemplateHead

#: holes punched into the skin: (skin landmark at the centre, radius mm)
HOLES = (("chk_l", 12.0), ("g", 10.0))
MIRROR = np.diag([-1.0, 1.0, 1.0, 1.0])


def scan_pose(angles_deg: tuple[float, float, float] = (30.0, -50.0, 20.0)) -> np.ndarray:
    """A 4 x 4 rigid map head frame → an arbitrary scanner frame (mm)."""
    from scipy.spatial.transform import Rotation

    m = np.eye(4)
    m[:3, :3] = Rotation.from_euler("xyz", angles_deg, degrees=True).as_matrix()
    m[:3, 3] = (10.0, -300.0, 40.0)
    return m


def damaged_skin(
    head: TemplateHead, pose: np.ndarray | None = None, *, mirror: bool = False
) -> tuple[Mesh, LandmarkSet]:
    """``head``'s skin with two discs of triangles removed, mapped by ``pose`` (after a
    reflection of x when ``mirror``), and its skin landmarks in the same frame."""
    skin = head.skin
    at = head.skin_landmarks.as_dict()
    centres = skin.vertices[skin.faces].mean(axis=1)
    keep = np.ones(skin.n_faces, bool)
    for code, radius in HOLES:
        keep &= np.linalg.norm(centres - at[code], axis=1) > radius
    m = (scan_pose() if pose is None else pose) @ (MIRROR if mirror else np.eye(4))
    faces = skin.faces[keep]
    if mirror:
        faces = faces[:, ::-1]
    v = skin.vertices @ m[:3, :3].T + m[:3, 3]
    return Mesh(v, faces), head.skin_landmarks.transformed(m)


def _cylinder(centre_xz, radius: float, y0: float, y1: float, n: int = 72, rings: int = 16) -> Mesh:
    """A closed upright cylinder, wound outward (side normals radial, caps up and down), mm."""
    a = np.linspace(0.0, 2 * np.pi, n, endpoint=False)
    ys = np.linspace(y0, y1, rings)
    ring = np.stack([radius * np.sin(a), np.zeros(n), radius * np.cos(a)], axis=1)
    v = [ring + (centre_xz[0], y, centre_xz[1]) for y in ys]
    v = np.vstack(v + [[(centre_xz[0], y0, centre_xz[1]), (centre_xz[0], y1, centre_xz[1])]])
    faces = []
    for r in range(rings - 1):
        for i in range(n):
            j = (i + 1) % n
            a0, a1, b0, b1 = r * n + i, r * n + j, (r + 1) * n + i, (r + 1) * n + j
            faces += [(a0, a1, b1), (a0, b1, b0)]
    bottom, top = len(v) - 2, len(v) - 1
    for i in range(n):
        j = (i + 1) % n
        faces.append((bottom, j, i))
        faces.append((top, (rings - 1) * n + i, (rings - 1) * n + j))
    return Mesh(v, np.array(faces))


def crowned_bust(head: TemplateHead) -> tuple[Mesh, dict]:
    """``head``'s skin below the brow under a tall crown wider than the head (like the
    Nefertiti bust: most of the surface is not a face); head frame, mm.  (One crown: a
    second piece of similar size far away would be refused as a second body.)
    Returns the mesh and the skin landmarks ``{code: position}``."""
    skin = head.skin
    at = head.skin_landmarks.as_dict()
    brow = at["g"][1] + 8.0
    centres = skin.vertices[skin.faces].mean(axis=1)
    keep = (centres[:, 1] < brow) & (centres[:, 1] > at["gn"][1] - 60.0)
    face = Mesh(skin.vertices, skin.faces[keep])
    head_z = float(np.median(skin.vertices[:, 2]))
    half_width = float(np.ptp(skin.vertices[:, 0])) / 2
    # the crown starts just above the face's top edge: a crown cutting through the face would be
    # a surface crossing itself, which fit-scan refuses as two bodies through each other
    top = float(face.vertices[np.unique(face.faces)][:, 1].max())
    crown = _cylinder((0.0, head_z - 15.0), 1.3 * half_width, top + 2.0, top + 126.0)
    return concatenate([face, crown]), at


def closed_eyes(head: TemplateHead, rings: int = 4) -> Mesh:
    """``head``'s skin with its palpebral openings closed by a lid-like cap each (rings
    toward the opening's centre, bulged 1.5 mm forward), wound like the skin (head frame)."""
    from workbench.core.mesh import boundary_loops

    skin = head.skin
    at = head.skin_landmarks.as_dict()
    vertices, faces = [skin.vertices], [skin.faces]
    n = skin.n_vertices
    for side in ("l", "r"):
        eye = 0.5 * (at[f"en_{side}"] + at[f"ex_{side}"])
        loop = min(
            boundary_loops(skin), key=lambda lp: np.linalg.norm(skin.vertices[lp].mean(0) - eye)
        )
        rim = skin.vertices[loop]
        centre = rim.mean(axis=0)
        ids = [np.asarray(loop)]
        for k in range(1, rings):
            r = 1.0 - k / rings
            ring = centre + r * (rim - centre) + [0.0, 0.0, 1.5 * (1 - r * r)]
            ids.append(np.arange(n, n + len(loop)))
            vertices.append(ring)
            n += len(loop)
        vertices.append((centre + [0.0, 0.0, 1.5])[None])
        tip = n
        n += 1
        m = len(loop)
        cap = []
        for a, b in zip(ids[:-1], ids[1:], strict=True):
            for i in range(m):
                j = (i + 1) % m
                cap += [(a[i], a[j], b[j]), (a[i], b[j], b[i])]
        last = ids[-1]
        cap += [(last[i], last[(i + 1) % m], tip) for i in range(m)]
        cap = np.asarray(cap)
        # wind the cap like the skin: its normals face forward (+z) like the lids
        tri = np.vstack(vertices)[cap]
        normal = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
        if normal[:, 2].sum() < 0:
            cap = cap[:, ::-1]
        faces.append(cap)
    return Mesh(np.vstack(vertices), np.vstack(faces))


def tube(path: np.ndarray, radius: float, n: int = 12) -> Mesh:
    """A closed tube of ``radius`` along the polyline ``path`` ``(k, 3)``, its ends capped,
    wound outward (mm, the path's frame): a cord or strap lying over a face."""
    path = np.asarray(path, float)
    along = np.gradient(path, axis=0)
    along /= np.linalg.norm(along, axis=1, keepdims=True)
    helper = np.where(np.abs(along[:, [1]]) < 0.9, [[0.0, 1.0, 0.0]], [[1.0, 0.0, 0.0]])
    u = np.cross(along, helper)
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    w = np.cross(along, u)
    a = np.linspace(0.0, 2 * np.pi, n, endpoint=False)
    rings = path[:, None] + radius * (
        np.cos(a)[None, :, None] * u[:, None] + np.sin(a)[None, :, None] * w[:, None]
    )
    k = len(path)
    v = np.vstack([rings.reshape(-1, 3), path[[0, -1]]])
    faces = []
    for r in range(k - 1):
        for i in range(n):
            j = (i + 1) % n
            a0, a1, b0, b1 = r * n + i, r * n + j, (r + 1) * n + i, (r + 1) * n + j
            faces += [(a0, b0, b1), (a0, b1, a1)]
    first, last = k * n, k * n + 1
    for i in range(n):
        j = (i + 1) % n
        faces += [(first, i, j), (last, (k - 1) * n + j, (k - 1) * n + i)]
    mesh = Mesh(v, np.array(faces))
    # (wound outward whichever way u, w turn: the volume's sign)
    tri = mesh.vertices[mesh.faces]
    volume = np.einsum("ij,ij->i", tri[:, 0], np.cross(tri[:, 1], tri[:, 2])).sum()
    return mesh if volume > 0 else mesh.reversed_winding()
