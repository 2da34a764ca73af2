"""Moving what is drawn in place: new point coordinates (and normals, colour values) for an
existing actor, without re-creating it — the interactive previews (a dragged landmark or
guide, the build slider, an animation frame, another age).

Points are ``(n, 3)`` in mm, with the count and order of the data the actor was drawn
from; the actor keeps its colouring and state.  The caller asks its view for a render.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from vtkmodules.util.numpy_support import vtk_to_numpy

from workbench.core.mesh import Mesh
from workbench.core.normals import vertex_normals


def source_data(actor: Any) -> Any:
    """The dataset ``actor`` was drawn from (the one to move points in).

    A surface coloured by scalars reaches its mapper through a pass-through
    algorithm of pyvista's (it sets the active scalars), whose output stays
    empty until the first render and is a shallow copy after it: the data is
    the producer's at the top of the mapper's input pipeline.
    """
    mapper = actor.GetMapper()
    algorithm = mapper.GetInputAlgorithm()
    while (
        algorithm is not None
        and algorithm.GetNumberOfInputPorts() > 0
        and algorithm.GetNumberOfInputConnections(0) > 0
    ):
        algorithm = algorithm.GetInputAlgorithm(0, 0)
    data = algorithm.GetOutputDataObject(0) if algorithm is not None else None
    return data if data is not None else mapper.GetInput()


def mapper_dataset(actor: Any) -> Any:
    """The polydata an actor of ``plotter.add_mesh`` draws (mm): pyvista's mapper dataset.

    Not ``GetMapper().GetInput()``: with scalars the mapper is fed through a
    pipeline connection, and its input is an empty output until the first render.
    """
    return actor.mapper.dataset


def drawn_points(data: Any) -> np.ndarray:
    """A copy of the points (mm) of a VTK dataset."""
    return np.array(vtk_to_numpy(data.GetPoints().GetData()), dtype=float)


def move_points(actor: Any, points: np.ndarray) -> None:
    """Move the points of ``actor``'s :func:`source_data`; smooth-shaded triangle
    surfaces get their vertex normals recomputed (:func:`triangle_vertex_normals`)."""
    data = source_data(actor)
    new = np.asarray(points, dtype=float).reshape(-1, 3)
    vtk_points = data.GetPoints()
    if vtk_points is None or new.shape[0] != vtk_points.GetNumberOfPoints():
        raise ValueError(f"expected {data.GetNumberOfPoints()} points, got {new.shape[0]}")
    vtk_to_numpy(vtk_points.GetData())[:] = new
    vtk_points.Modified()
    normals = data.GetPointData().GetNormals()
    if normals is not None and data.GetPolys().IsHomogeneous() == 3:  # triangles only
        vtk_to_numpy(normals)[:] = triangle_vertex_normals(new, data)
        normals.Modified()
    data.Modified()


def triangle_vertex_normals(points: np.ndarray, data: Any) -> np.ndarray:
    """Unit vertex normals of the triangles of ``data`` at ``points``.

    Area-weighted, as :attr:`Mesh.vertex_normals` (the normals the surface
    was first drawn with), so the shading does not jump on the first update.
    """
    cells = vtk_to_numpy(data.GetPolys().GetConnectivityArray()).reshape(-1, 3)
    t = points[cells]
    cross = np.cross(t[:, 1] - t[:, 0], t[:, 2] - t[:, 0])  # length = 2 × area
    n = len(points)
    flat = cells.ravel()
    # float64 (bincount with weights), whatever numpy's stubs say
    out: np.ndarray = np.column_stack(
        [np.bincount(flat, np.repeat(cross[:, k], 3), minlength=n) for k in range(3)]
    )
    out /= np.maximum(np.linalg.norm(out, axis=1, keepdims=True), 1e-12)
    return out


def set_array(vtk_array: Any, values: np.ndarray) -> None:
    """Overwrite a VTK array with ``values`` (reshaped to it) and mark it modified."""
    target = vtk_to_numpy(vtk_array)
    target[:] = np.asarray(values, float).reshape(target.shape)
    vtk_array.Modified()


def set_input_points(actor: Any, points: np.ndarray, first: int = 0) -> None:
    """Overwrite points ``first …`` of the mapper input of ``actor`` (a plain surface, lines
    or markers: no scalars pipeline) with ``points``; normals are left as they are."""
    data = actor.GetMapper().GetInput()
    pts = vtk_to_numpy(data.GetPoints().GetData())
    pts[first : first + len(points)] = points
    data.GetPoints().Modified()


def set_points_and_normals(actor: Any, points: np.ndarray, normals: np.ndarray) -> None:
    """Overwrite the points and point normals of ``actor``'s :func:`source_data` (any
    mapper pipeline, e.g. per-vertex colours) with ``points`` and ``normals`` given by the
    caller: nothing is recomputed (hair ribbons carry their own shading normals)."""
    data = source_data(actor)
    set_array(data.GetPoints().GetData(), points)
    data.GetPoints().Modified()
    vtk_normals = data.GetPointData().GetNormals()
    if vtk_normals is not None:
        set_array(vtk_normals, normals)
    data.Modified()


def set_surface_points(actor: Any, points: np.ndarray, faces: np.ndarray, vf: Any = None) -> None:
    """Move a surface actor's polydata points (and its normals) in place.

    ``vf``: the part's ``Mesh.vertex_faces_matrix`` (its topology does not
    change), so a frame's normals are one sparse product, not a rebuild.
    """
    data = actor.GetMapper().GetInput()
    vtk_points = data.GetPoints()
    new = np.asarray(points, float)
    vtk_to_numpy(vtk_points.GetData())[:] = new
    vtk_points.Modified()
    normals = data.GetPointData().GetNormals()
    if normals is not None:
        if vf is None:
            vtk_to_numpy(normals)[:] = vertex_normals(Mesh(new, faces))
        else:
            t = new[faces]
            summed = np.asarray(vf @ np.cross(t[:, 1] - t[:, 0], t[:, 2] - t[:, 0]))
            length = np.linalg.norm(summed, axis=1, keepdims=True)
            vtk_to_numpy(normals)[:] = summed / np.where(length > 0, length, 1.0)
        normals.Modified()
    data.Modified()
