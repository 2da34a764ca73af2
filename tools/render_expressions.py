"""Render the expression palette on a head: one picture of tiles for the README (issue 14).

    python tools/render_expressions.py HEAD OUT.png [--title TEXT]

HEAD is what ``workbench animate`` takes (a template pack, a reconstruction
folder, ``reference:male|female``).  Each tile is the skin simulated by
:class:`workbench.services.animation.animator.Animator` to rest under one expression
of :data:`workbench.services.animation.animator.EXPRESSIONS` (the six basic
emotions, neutral, smile, eye closure), drawn from the front, slightly
above and to the side, with the same camera for every tile.  Units mm, the
head frame (the Animator works there).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

NAMES = (
    "neutral",
    "smile",
    "happiness",
    "sadness",
    "surprise",
    "fear",
    "anger",
    "disgust",
    "eye_closure",
)


def main(argv: list[str]) -> int:
    import pyvista as pv

    from workbench.cli.animate_cmd import load_head
    from workbench.services.animation.animator import Animator

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("head")
    ap.add_argument("out", type=Path)
    ap.add_argument("--title", default="")
    ap.add_argument("--tile", type=int, default=340)
    args = ap.parse_args(argv)

    head, _, _ = load_head(args.head)
    anim = Animator(head)
    skins = {}
    for name in NAMES:
        anim.set_expression(name)
        anim.settle()
        skins[name] = anim.skin_in_head_frame().copy()
    faces = np.hstack([np.full((anim.head.skin.n_faces, 1), 3), anim.head.skin.faces]).ravel()
    cols = 3
    rows = int(np.ceil(len(NAMES) / cols))
    plotter = pv.Plotter(
        off_screen=True, shape=(rows, cols), window_size=(cols * args.tile, rows * args.tile)
    )
    lm = anim.head.skin_landmarks.as_dict()
    focus = (
        (lm["prn"] + lm["n"] + lm["pg"]) / 3
        if all(k in lm for k in ("prn", "n", "pg"))
        else (anim.head.skin.vertices.mean(axis=0))
    )
    eyes = anim.head.meshes["eyes"]
    eye_faces = np.hstack([np.full((eyes.n_faces, 1), 3), eyes.faces]).ravel()
    for i, name in enumerate(NAMES):
        plotter.subplot(i // cols, i % cols)
        plotter.add_mesh(
            pv.PolyData(skins[name], faces), color="#d9a982", smooth_shading=True, specular=0.15
        )
        plotter.add_mesh(
            pv.PolyData(eyes.vertices, eye_faces), color="#f2f2f2", smooth_shading=True
        )
        plotter.add_text(name.replace("_", " "), font_size=11, color="black")
        plotter.set_background("white")
        plotter.camera.focal_point = tuple(focus)
        plotter.camera.position = tuple(focus + np.array([110.0, 40.0, 380.0]))
        plotter.camera.up = (0.0, 1.0, 0.0)
        plotter.camera.parallel_projection = True
        plotter.camera.parallel_scale = 105.0
    if args.title:
        plotter.subplot(0, 0)
        plotter.add_text(args.title, position="lower_left", font_size=8, color="#444444")
    args.out.parent.mkdir(parents=True, exist_ok=True)
    plotter.screenshot(str(args.out))
    plotter.close()
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
