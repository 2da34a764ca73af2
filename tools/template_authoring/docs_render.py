"""Render the documentation images of the template skin (male reference) with placeholder eyeballs.

Same style as workbench.render.snapshots.render_surfaces (white background, smooth shading,
HEAD frame: front looks at the face, side at the subject's right profile), but framed on the
skin alone so that the whole head and neck stump fit in the picture.
"""
import os
from pathlib import Path
import numpy as np
from PIL import Image
import pyvista as pv
from workbench.core.headgen import build_skin
from workbench.core.headgen.eyes import icosphere
from workbench.core.mesh import Mesh
from workbench.render.snapshots import to_polydata, view_directions

os.environ.setdefault("VTK_DEFAULT_OPENGL_WINDOW", "vtkEGLRenderWindow")
s = build_skin("male")
unit = icosphere(3)
layers = [(s.mesh, "#e3bfa3")]
for side, (c, r) in s.eyeballs.items():
    layers.append((Mesh(c + unit.vertices * r, unit.faces), "#f3f1ec"))
    layers.append((Mesh(c + np.array([0, 0, r - 4.6]) + unit.vertices * 5.9, unit.faces), "#3b2c22"))
centre = s.mesh.bounds.mean(axis=0)
for view in ("front", "side", "three_quarter"):
    p = str(Path(__file__).resolve().parents[2] / "docs" / "images" / f"template_skin_{view}.png")
    pl = pv.Plotter(off_screen=True, window_size=(520, 600), border=False)
    pl.set_background("white")
    for m, col in layers:
        pl.add_mesh(to_polydata(m), color=col, smooth_shading=True, specular=0.2)
    d, up = view_directions(view, np.array([0, 0, 1.0]), np.array([0, 1.0, 0]))
    pl.camera.focal_point = centre
    pl.camera.position = centre + d * 660.0
    pl.camera.up = up
    pl.camera.view_angle = 30.0
    pl.add_text(f"template skin (male), {view.replace('_', ' ')}", font_size=9, color="black")
    pl.screenshot(p)
    pl.close()
    Image.open(p).convert("RGB").save(p, optimize=True)
    print(p, os.path.getsize(p))
