"""Scan colours read from PLY / OBJ (+ MTL + image), and the coloured skin written back."""

from __future__ import annotations

import numpy as np
import pytest
from PIL import Image

from workbench.core.colour_transfer import ScanColours, sample_image, transfer_colours
from workbench.core.errors import InputError
from workbench.core.mesh import Mesh
from workbench.io.mesh_formats import ply
from workbench.io.meshes import read_mesh, write_mesh
from workbench.io.scan_colours import read_scan_colours
from workbench.io.skin_colour_export import write_coloured_skin


def grid_mesh(n: int = 6) -> tuple[np.ndarray, np.ndarray]:
    """A flat n x n grid (mm) as quads: vertices and quad corner indices."""
    yy, xx = np.mgrid[0:n, 0:n]
    verts = np.c_[xx.ravel() * 10.0, yy.ravel() * 10.0, np.zeros(n * n)]
    quads = []
    for j in range(n - 1):
        for i in range(n - 1):
            a = j * n + i
            quads.append([a, a + 1, a + n + 1, a + n])
    return verts, np.array(quads)


def test_binary_and_ascii_ply_colours_align(tmp_path):
    verts, quads = grid_mesh()
    faces = np.r_[quads[:, [0, 1, 2]], quads[:, [0, 2, 3]]]
    rgb = (np.arange(len(verts) * 3).reshape(-1, 3) * 7 % 256).astype(np.uint8)
    for binary in (True, False):
        path = tmp_path / f"c{binary}.ply"
        path.write_bytes(ply.encode(verts, faces, binary=binary, vertex_rgb=rgb))
        mesh = read_mesh(path).mesh
        colours = read_scan_colours(path)
        assert colours is not None and colours.kind == "vertex"
        np.testing.assert_array_equal(colours.vertex_rgb, rgb)
        assert colours.n_vertices == mesh.n_vertices
        np.testing.assert_array_equal(colours.faces, mesh.faces)


def test_float_ply_colours_with_alpha_and_quads(tmp_path):
    verts, quads = grid_mesh(3)
    cols = np.linspace(0, 1, len(verts) * 3).reshape(-1, 3)
    header = (
        f"ply\nformat ascii 1.0\nelement vertex {len(verts)}\n"
        "property float x\nproperty float y\nproperty float z\n"
        "property float red\nproperty float green\nproperty float blue\nproperty float alpha\n"
        f"element face {len(quads)}\nproperty list uchar int vertex_indices\nend_header\n"
    )
    rows = "".join(
        " ".join(map(str, [*v, *c, 1.0])) + "\n" for v, c in zip(verts, cols, strict=True)
    )
    faces = "".join("4 " + " ".join(map(str, q)) + "\n" for q in quads)
    path = tmp_path / "f.ply"
    path.write_text(header + rows + faces)
    colours = read_scan_colours(path)
    assert colours is not None
    np.testing.assert_array_equal(colours.vertex_rgb, np.rint(cols * 255).astype(np.uint8))
    assert read_mesh(path).mesh.n_faces == 2 * len(quads)


def test_plain_meshes_have_no_colours(tmp_path):
    verts, quads = grid_mesh(3)
    mesh = Mesh(verts, np.r_[quads[:, [0, 1, 2]], quads[:, [0, 2, 3]]])
    for name in ("p.ply", "p.obj", "p.stl"):
        write_mesh(tmp_path / name, mesh)
        assert read_scan_colours(tmp_path / name) is None
    with pytest.raises(InputError, match=r"p\.stl.*no texture coordinates"):
        read_scan_colours(tmp_path / "p.stl", texture=tmp_path / "none.png")


def test_obj_vertex_colours(tmp_path):
    path = tmp_path / "vc.obj"
    path.write_text("v 0 0 0 1 0 0\nv 10 0 0 0 1 0\nv 0 10 0 0 0 0.5\nv 10 10 0 1 1 1\nf 1 2 4 3\n")
    colours = read_scan_colours(path)
    assert colours is not None
    np.testing.assert_array_equal(
        colours.vertex_rgb, [[255, 0, 0], [0, 255, 0], [0, 0, 128], [255, 255, 255]]
    )
    np.testing.assert_allclose(read_mesh(path).mesh.vertices[:, 0], [0, 10, 0, 10])


def write_textured_obj(folder, *, image_name="tex.png", make_image=True):
    """A 5 x 5 quad grid with per-corner vt (polygons, negative vt indices on one row)."""
    verts, quads = grid_mesh()
    uv = verts[:, :2] / 50.0
    lines = ["mtllib grid.mtl", "o grid"]
    lines += [f"v {x} {y} {z}" for x, y, z in verts]
    lines += [f"vt {u} {v}" for u, v in uv]
    lines += ["usemtl painted"]
    for k, q in enumerate(quads):
        if k == 0:  # relative texture indices
            lines.append("f " + " ".join(f"{a + 1}/{a - len(uv)}/1" for a in q))
        else:
            lines.append("f " + " ".join(f"{a + 1}/{a + 1}" for a in q))
    (folder / "grid.obj").write_text("\n".join(lines) + "\n")
    (folder / "grid.mtl").write_text(f"newmtl painted\nKd 1 1 1\nmap_Kd -s 1 1 1 {image_name}\n")
    h, w = 64, 80
    yy, xx = np.mgrid[0:h, 0:w]
    img = np.stack([xx * 3, yy * 3, np.full_like(xx, 90)], axis=-1).astype(np.uint8)
    if make_image:
        Image.fromarray(img, "RGB").save(folder / image_name)
    return folder / "grid.obj", uv, img


def test_textured_obj_aligned_with_read_mesh(tmp_path):
    path, uv, img = write_textured_obj(tmp_path)
    mesh = read_mesh(path).mesh
    colours = read_scan_colours(path)
    assert colours is not None and colours.kind == "texture"
    assert colours.corner_uv is not None and colours.image is not None
    np.testing.assert_array_equal(colours.image, img)
    np.testing.assert_array_equal(colours.faces, mesh.faces)
    # corner k of triangle f is vertex mesh.faces[f, k]: its vt is that vertex's uv
    np.testing.assert_allclose(colours.corner_uv, uv[mesh.faces])


def test_texture_override_and_bad_textures(tmp_path):
    path, _, _ = write_textured_obj(tmp_path)
    other = np.full((8, 8, 3), 33, np.uint8)
    Image.fromarray(other).convert("L").save(tmp_path / "grey.jpg")  # greyscale: made RGB
    colours = read_scan_colours(path, texture=tmp_path / "grey.jpg")
    assert colours is not None and colours.image is not None
    assert colours.image.shape == (8, 8, 3) and abs(int(colours.image[4, 4, 0]) - 33) <= 2
    (tmp_path / "broken.png").write_bytes(b"\x89PNG\r\n not really")
    with pytest.raises(InputError, match=r"broken\.png.*cannot be read"):
        read_scan_colours(path, texture=tmp_path / "broken.png")
    with pytest.raises(InputError, match=r"missing\.png.*not found"):
        read_scan_colours(path, texture=tmp_path / "missing.png")
    plain = tmp_path / "plain.obj"
    plain.write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")
    with pytest.raises(InputError, match=r"plain\.obj.*no texture coordinates"):
        read_scan_colours(plain, texture=tmp_path / "grey.jpg")


def test_material_image_missing_is_named(tmp_path):
    path, _, _ = write_textured_obj(tmp_path, image_name="gone.png", make_image=False)
    with pytest.raises(InputError, match=r"gone\.png.*map_Kd.*not found"):
        read_scan_colours(path)
    read_mesh(path)  # the mesh itself still reads


def test_corners_without_vt_drop_the_uvs_with_a_note(tmp_path):
    path = tmp_path / "mixed.obj"
    path.write_text(
        "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 1 1 0\nvt 0 0\nvt 1 0\nvt 0 1\nf 1/1 2/2 3/3\nf 2 4 3\n"
    )
    assert read_scan_colours(path) is None
    assert any("no texture coordinate" in m for m in read_mesh(path).messages)
    with pytest.raises(InputError, match="no texture coordinates.*some face corners"):
        read_scan_colours(path, texture=path)


def test_two_textures_side_by_side(tmp_path):
    verts = np.array([[0, 0, 0], [10, 0, 0], [0, 10, 0], [10, 10, 0]], float)
    (tmp_path / "two.obj").write_text(
        "mtllib two.mtl\n"
        + "".join(f"v {x} {y} {z}\n" for x, y, z in verts)
        + "vt 0.5 0.5\nusemtl a\nf 1/1 2/1 3/1\nusemtl b\nf 2/1 4/1 3/1\n"
    )
    (tmp_path / "two.mtl").write_text("newmtl a\nmap_Kd a.png\nnewmtl b\nmap_Kd b.png\n")
    Image.fromarray(np.full((4, 4, 3), (200, 0, 0), np.uint8)).save(tmp_path / "a.png")
    Image.fromarray(np.full((8, 6, 3), (0, 0, 200), np.uint8)).save(tmp_path / "b.png")
    colours = read_scan_colours(tmp_path / "two.obj")
    assert colours is not None and colours.image is not None and colours.corner_uv is not None
    assert colours.image.shape == (8, 10, 3)
    got = sample_image(colours.image, colours.corner_uv[:, 0])
    np.testing.assert_allclose(got, [[200, 0, 0], [0, 0, 200]])


def test_written_coloured_skin_reads_back(tmp_path, head_male):
    skin = head_male.skin
    lo, hi = skin.vertices.min(axis=0), skin.vertices.max(axis=0)
    rgb = np.rint(20 + 200 * (skin.vertices - lo) / (hi - lo)).astype(np.uint8)
    scan_colours = ScanColours("scan.ply", skin.n_vertices, skin.faces, vertex_rgb=rgb)
    colours = transfer_colours(skin, skin, scan_colours)
    assert colours.observed.all()
    assert np.abs(colours.rgb.astype(int) - rgb).max() <= 1
    for scan in (None, skin):  # vertex-colour atlas, and texels sampled from the scan
        folder = tmp_path / ("blend" if scan is None else "sampled")
        folder.mkdir()
        files = write_coloured_skin(
            folder, skin, colours, atlas_size=512, scan=scan, scan_colours=scan_colours
        )
        assert [f.name for f in files] == [
            "skin_colour.ply",
            "skin_textured.obj",
            "skin_textured.mtl",
            "skin_texture.png",
        ]
        back = read_mesh(folder / "skin_colour.ply").mesh
        np.testing.assert_allclose(back.vertices, skin.vertices)
        ply_colours = read_scan_colours(folder / "skin_colour.ply")
        assert ply_colours is not None
        np.testing.assert_array_equal(ply_colours.vertex_rgb, colours.rgb)
        assert "units: mm" in ply.header_comments(folder / "skin_colour.ply")
        obj_mesh = read_mesh(folder / "skin_textured.obj").mesh
        np.testing.assert_array_equal(obj_mesh.faces, skin.faces)
        tex = read_scan_colours(folder / "skin_textured.obj")
        assert tex is not None and tex.image is not None and tex.corner_uv is not None
        assert tex.image.shape[0] == tex.image.shape[1] >= 512
        # each triangle corner samples (bilinear) its vertex's colour from the atlas
        at_corners = sample_image(tex.image, tex.corner_uv.reshape(-1, 2))
        err = np.abs(at_corners - colours.rgb[skin.faces].reshape(-1, 3))
        assert np.median(err) <= 2.0 and err.max() <= 12.0
        # patch interiors: the centroid samples the mean of the corners' colours
        centre = sample_image(tex.image, tex.corner_uv.mean(axis=1))
        err_c = np.abs(centre - colours.rgb[skin.faces].astype(float).mean(axis=1))
        assert np.percentile(err_c, 95) <= 3.0
