"""Render helpers for authoring (pyvista, off-screen)."""
from __future__ import annotations

import os

import numpy as np

os.environ.setdefault("VTK_DEFAULT_OPENGL_WINDOW", "vtkEGLRenderWindow")


def polydata(v, f):
    import pyvista as pv
    faces = np.hstack([np.full((len(f), 1), 3, np.int64), f]).ravel()
    return pv.PolyData(np.asarray(v, float), faces)


VIEWS = {
    "front": (0, 0, 1),
    "side": (-1, 0, 0),       # subject's right profile
    "left": (1, 0, 0),
    "tq": (-0.7071, 0, 0.7071),
    "tql": (0.7071, 0, 0.7071),
    "back": (0, 0, -1),
    "top": (0, 1, 0.0001),
    "below": (0, -0.6, 0.8),
    "above": (0, 0.5, 0.86),
}


def render(meshes, path, views=("front", "side", "tq"), focus=None, dist=520.0, size=(420, 500),
           edges=False, points=None, parallel=False, scale=None, colors=None):
    import pyvista as pv
    pl = pv.Plotter(off_screen=True, shape=(1, len(views)), window_size=(size[0] * len(views), size[1]),
                    border=False)
    if not isinstance(meshes, list):
        meshes = [meshes]
    for i, vname in enumerate(views):
        pl.subplot(0, i)
        pl.set_background("white")
        for k, (v, f) in enumerate(meshes):
            col = (colors[k] if colors else "#e8c4a8")
            pl.add_mesh(polydata(v, f), color=col, smooth_shading=not edges, show_edges=edges,
                        edge_color="#555555", line_width=0.5, specular=0.15)
        if points is not None and len(points):
            pl.add_points(np.asarray(points, float), color="red", point_size=6, render_points_as_spheres=True)
        d = np.asarray(VIEWS[vname], float)
        d /= np.linalg.norm(d)
        c = np.asarray(focus if focus is not None else meshes[0][0].mean(0), float)
        pl.camera.focal_point = c
        pl.camera.position = c + d * dist
        pl.camera.up = (0, 1, 0) if vname != "top" else (0, 0, 1)
        if parallel:
            pl.camera.enable_parallel_projection()
            pl.camera.parallel_scale = scale or dist * 0.3
        pl.camera.view_angle = 30.0
        pl.add_text(vname, font_size=9, color="black")
    pl.screenshot(path)
    pl.close()
    return path


def mc_preview(f, box=((-100, 100), (-190, 145), (-115, 125)), h=2.0):
    from skimage.measure import marching_cubes
    xs = np.arange(box[0][0], box[0][1] + h, h)
    ys = np.arange(box[1][0], box[1][1] + h, h)
    zs = np.arange(box[2][0], box[2][1] + h, h)
    g = np.stack(np.meshgrid(xs, ys, zs, indexing="ij"), -1)
    vals = np.empty(g.shape[:3])
    for i in range(len(xs)):
        vals[i] = f(g[i])
    v, faces, _, _ = marching_cubes(vals, 0.0, spacing=(h, h, h))
    v += np.array([xs[0], ys[0], zs[0]])
    return v, faces[:, ::-1]
