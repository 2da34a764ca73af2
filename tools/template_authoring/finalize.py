"""Build, relax, fit and export the half-head control mesh as JSON."""
from __future__ import annotations

import json
import sys
from pathlib import Path
import time

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import build  # noqa: E402
import fit  # noqa: E402
import geom  # noqa: E402
import headsdf as H  # noqa: E402
import layout  # noqa: E402
import mirror  # noqa: E402

OUT = sys.argv[1] if len(sys.argv) > 1 else "skin_control_mesh.json"


def neighbours(F, n):
    nb = [set() for _ in range(n)]
    for a, b, c in F:
        nb[a].update((b, c))
        nb[b].update((a, c))
        nb[c].update((a, b))
    return nb


def relax(B, F, rounds=1, alpha=0.6):
    P = np.array(B.P)
    n = len(P)
    nb = neighbours(F, n)
    free = np.arange(B.free0, n)
    for _ in range(rounds):
        newp = P.copy()
        for i in free:
            if nb[i]:
                c = P[list(nb[i])].mean(0)
                newp[i] = (1 - alpha) * P[i] + alpha * c
        newp[free] = geom.project(newp[free])
        newp[free, 0] = np.maximum(newp[free, 0], 0.5)
        P = newp
    for i in free:
        B.P[i] = P[i]
        B.V[i] = P[i]


def classify(B, F, n_struct_faces, tr_y):
    P = np.array(B.P)
    labels = list(B.labels)
    for f in F[n_struct_faces:]:
        c = P[f].mean(0)
        if H.nose(c[None])[0] < 1.2 and c[1] > -31 and c[2] > 78:
            lab = "nose"
        elif c[1] > tr_y - 2 or (c[2] <= 5 and c[1] > -45):
            lab = "scalp"
        elif c[1] < -108 or (c[2] < -25 and c[1] < -45) or (c[2] < 30 and c[1] < -85):
            lab = "neck"
        else:
            lab = "face"
        labels.append(lab)
    # split eyelids and lips
    en, ex = np.array(layout.EN), np.array(layout.EX)
    for k, f in enumerate(F[:n_struct_faces]):
        c = P[f].mean(0)
        if labels[k] == "eyelid":
            t = np.clip((c[0] - en[0]) / (ex[0] - en[0]), 0, 1)
            base = en[1] + t * (ex[1] - en[1])
            labels[k] = "eyelid_upper" if c[1] > base else "eyelid_lower"
        elif labels[k] == "lip":
            labels[k] = "upper_lip" if c[1] > layout.sto_y(c[0]) else "lower_lip"
    return labels


def dumps_readable(data):
    """JSON with one vertex / face / ring per line (diff- and hand-edit-friendly)."""
    parts = []
    for k, v in data.items():
        if k in ("vertices", "faces", "creases"):
            inner = ",\n".join("  " + json.dumps(x, separators=(",", ":")) for x in v)
            parts.append(f"{json.dumps(k)}: [\n{inner}\n ]")
        elif k in ("rings", "landmarks", "openings"):
            inner = ",\n".join(f"  {json.dumps(a)}: {json.dumps(b, separators=(',', ':'), ensure_ascii=False)}"
                                for a, b in v.items())
            parts.append(f"{json.dumps(k)}: {{\n{inner}\n }}")
        else:
            parts.append(f"{json.dumps(k)}: {json.dumps(v, separators=(',', ':'), ensure_ascii=False)}")
    return "{\n " + ",\n ".join(parts) + "\n}\n"


def main():
    t0 = time.time()
    B = build.assemble()
    for r in range(2):
        F, miss = build.triangulate(B, verbose=False)
        relax(B, F)
    F, miss = build.triangulate(B)
    n_struct = len(B.faces)
    P = np.array(B.P)
    F = build.orient(F, P)
    # ensure outward: the forehead face normals point +z/+y
    from workbench.core.mesh import Mesh, validate
    P2, F2, mp = mirror.mirror(P, F)
    m = Mesh(P2, F2)
    i = int(np.argmax(P2[:, 2]))
    fn = m.face_normals[(F2 == i).any(1)].mean(0)
    if fn[2] < 0:
        F = F[:, ::-1]
        P2, F2, mp = mirror.mirror(P, F)
    tr_y = P[B.LM["tr"][1]][1]
    labels = classify(B, F, n_struct, tr_y)
    kinds = np.array(B.kind)
    half_mid = np.abs(P[:, 0]) < 1e-9
    sdf_full = np.concatenate([kinds == "sdf", (kinds == "sdf")[~half_mid]])
    ids = B.ids
    m1 = ids["mouth_m1"]
    cr = [(int(a), int(b)) for a, b in zip(m1[:-1], m1[1:])]
    cr_full = cr + [(int(mp[a]), int(mp[b])) for a, b in cr]
    corners = [int(ids["eye_r0"][0]), int(ids["eye_r0"][8]), int(ids["mouth_m0"][6]), int(ids["mouth_m1"][6])]
    corners_full = corners + [int(mp[c]) for c in corners]
    midline = np.nonzero(np.abs(P2[:, 0]) < 1e-9)[0]

    # ear: parametric targets for the fine vertices
    C, sub = fit.fit(P2, F2, sdf_full, creases=np.array(cr_full), corners=np.array(corners_full), iters=3,
                     midline=midline)
    # exact symmetry
    n = len(P)
    Ch = C[:n].copy()
    Ch[half_mid, 0] = 0.0
    Cr = C[mp[:n]] * np.array([-1, 1, 1])
    Ch[~half_mid] = 0.5 * (Ch[~half_mid] + Cr[~half_mid])
    print("validate full control:", validate(Mesh(P2, F2)).summary())

    # landmarks: code -> half vertex id
    lm = {}
    for code, (ring, idx) in B.LM.items():
        lm[code] = int(idx) if ring == "vertex" else int(ids[ring][idx])
    # ear landmarks
    rim = ids["ear_rim"]
    att = ids["ear_att"]
    front_rings = np.concatenate([ids["ear_rim"], ids["ear_f1"]])
    lm["sa"] = int(rim[np.argmax(Ch[rim, 1])])
    lm["sba"] = int(rim[np.argmin(Ch[rim, 1])])
    lm["pa"] = int(rim[np.argmin(Ch[rim, 2])])
    # preaurale: most anterior ear point at the level (along the ear axis) of postaurale
    cand = np.concatenate([ids["ear_rim"], ids["ear_f1"], ids["ear_att"]])
    u_of = lambda i: float((Ch[i] - layout.EAR_O) @ layout.E_U)  # noqa: E731
    u_pa = u_of(lm["pa"])
    near = [i for i in cand if abs(u_of(i) - u_pa) < 7.0]
    lm["pra"] = int(max(near, key=lambda i: Ch[i, 2]))
    lm["obs"] = int(att[np.argmax(Ch[att, 1])])
    lm["obi"] = int(att[np.argmin(Ch[att, 1])])
    f4 = [i for i in ids["ear_f4"] if Ch[i, 1] > -1.0]
    lm["t"] = int(max(f4, key=lambda i: Ch[i, 2]))
    lm["po"] = int(ids["ear_c"][0])

    rings = {k: [int(x) for x in v] for k, v in ids.items()}
    data = {
        "format": "workbench.skin_control_mesh",
        "version": 1,
        "units": "mm",
        "frame": ("HEAD: x toward the subject's left, x = 0 the midsagittal plane; y up, perpendicular to the "
                  "Frankfort Horizontal (FH: porions and orbitales at y = 0); z forward (toward the face); "
                  "origin on the midsagittal plane between the porions"),
        "symmetry": ("One half plus the midline is stored: every vertex has x >= 0. Vertices with x == 0 lie on "
                     "the midsagittal plane and are shared by both halves; every other vertex has a mirror "
                     "(-x, y, z) on the subject's right. Faces are listed for the left half only; the right "
                     "half is the mirror image with reversed winding."),
        "subdivision": ("Loop (1987) with boundary/crease curve rules; creases and corners listed below. "
                        "Vertex positions are fitted so that ONE Loop step gives the intended surface (level 1)."),
        "sex": "male (neutral); the female variant and the anthropometric fit are applied by "
               "workbench.core.headgen.skin from skin_parameters.json",
        "sources": {
            "kahler2003": ("Kähler K. A Head Model with Anatomical Structure for Facial Modeling and Animation. "
                           "Dr.-Ing. dissertation, Universität des Saarlandes 2003, ch. 5.1 (reference head: edges "
                           "aligned to facial features, tessellation adapted to deformability, FH alignment)."),
            "parke_waters1996": ("Parke FI, Waters K. Computer Facial Animation, A K Peters 1996, App. B "
                                 "(the simple face model Kähler starts from; topology idea only, no data used)."),
            "weinberg2016": ("Weinberg SM et al. The 3D Facial Norms database: part 1. Cleft Palate Craniofac J "
                             "53(6):e185-e197, 2016 (adult European means via Cliniface; the design of this neutral "
                             "male mesh is close to them and skin_parameters.json fits them exactly)."),
            "farkas1994": ("Farkas LG (ed.). Anthropometry of the Head and Face, 2nd ed., Raven Press 1994 "
                           "(landmark definitions; head length/breadth/height of the order used; not verified "
                           "against the book)."),
        },
        "design": ("Authored for this project: a male neutral head sculpted as a signed-distance field (cranium "
                   "superellipsoid, face loft with a displacement relief for orbits, brow, cheeks, lips; nose "
                   "pyramid with lobule, alae and nostrils), ears as a parametric flattened helix shell, lid "
                   "margins and inner lips explicit; feature rings laid out around eyes, mouth, nostrils, ears and "
                   "neck, Delaunay fill elsewhere; positions fitted through the Loop subdivision matrix. Design "
                   "values: n-gn ~126 mm, n-sn ~57, g-op ~197, vertex 128 mm above FH, soft nasion ~89 mm in "
                   "front of the porions, globes of radius 12 mm centred at (+-32.5, 13, 59.5)."),
        "vertices": [[round(float(v), 4) for v in p] for p in Ch],
        "faces": [[int(a), int(b), int(c)] for a, b, c in F],
        "face_regions": labels,
        "creases": [list(e) for e in cr],
        "corners": corners,
        "rings": rings,
        "openings": {
            "eye": {"ring": "eye_r0", "closed": True, "sided": True},
            "mouth": {"ring": "mouth_m0", "closed": False, "sided": False},
            "neck": {"ring": "neck_n3", "closed": False, "sided": False},
        },
        "landmarks": dict(sorted(lm.items())),
        "eye": {"centre": [float(v) for v in H.EYE_C], "radius": float(H.EYE_R),
                "note": "globe the left eye opening was designed around (right: mirror)"},
    }
    with open(OUT, "w", encoding="utf-8") as fh:
        fh.write(dumps_readable(data))
    print("wrote", OUT, len(Ch), "half vertices", len(F), "half faces", time.time() - t0)


if __name__ == "__main__":
    main()
