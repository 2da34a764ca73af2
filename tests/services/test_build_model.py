"""The body-build model: the table, build scores, regional depths, three faces and the band."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest

from workbench.core.errors import InputError
from workbench.io.build_model import BUILD_FACES, load_build_model
from workbench.io.tables import load_depth_table
from workbench.model.reconstruction_setup import SetupError, parse_bmi_build, parse_build
from workbench.services.tissue.dowels import DepthSettings, build_score, plan_dowels

ORIENT = ((0.0, 0.0, 1.0), (0.0, 1.0, 0.0))  # the generated skull: face +z, up +y


# ---------------------------------------------------------------- the table
def test_the_shipped_model_acts_least_on_the_forehead_and_most_on_the_cheeks() -> None:
    m = load_build_model()
    assert set(m.builds) == set(BUILD_FACES)
    assert m.builds["slender"] < m.builds["average"] < m.builds["heavy"]
    assert m.z("average") == pytest.approx(0.0) and m.z("normal") == m.z("average")
    assert m.z("obese") == m.z("heavy") > 1.5 and m.z("slender") < -0.5
    for thin in ("g", "n", "rhi"):
        for thick in ("zy_l", "go_r", "ecm2s_l", "mr_r"):
            assert m.loading(thin) < m.loading(thick)
    assert m.loading("zy_l") == m.loading("zy_r") == m.loading("zy")
    assert m.loading("no_such_code") == 0.0
    # every row is a T-Table landmark (side suffixes dropped), and the model says it is one
    table = {c.removesuffix("_l").removesuffix("_r") for c in load_depth_table("ttable_2023").codes}
    assert set(m.r) <= table
    assert m.meta["kind"] == "model" and m.meta["sources"]


def _user_model(tmp_path: Path, csv_rows: str, **meta_changes) -> Path:
    shipped = load_build_model()
    assert shipped.path is not None
    meta = json.loads(shipped.path.with_suffix(".meta.json").read_text(encoding="utf-8"))
    meta.update(meta_changes)
    (tmp_path / "mine.meta.json").write_text(json.dumps(meta), encoding="utf-8")
    p = tmp_path / "mine.csv"
    p.write_text("landmark_code,region,r,basis\n" + csv_rows, encoding="utf-8")
    return p


def test_a_user_model_is_read_and_bad_values_are_refused_naming_file_and_line(
    tmp_path: Path,
) -> None:
    ok = load_build_model(_user_model(tmp_path, "g,forehead,0.1,mine\nzy,cheek,0.9,mine\n"))
    assert ok.loading("zy_l") == 0.9 and ok.loading("g") == 0.1
    with pytest.raises(InputError, match=r"mine\.csv.*line 3: r = 1\.5 is outside 0\.\.1"):
        load_build_model(_user_model(tmp_path, "g,forehead,0.1,x\nzy,cheek,1.5,x\n"))
    with pytest.raises(InputError, match="appears twice"):
        load_build_model(_user_model(tmp_path, "g,a,0.1,x\ng,a,0.2,x\n"))
    with pytest.raises(InputError, match="must rise"):
        load_build_model(
            _user_model(tmp_path, "g,a,0.1,x\n", builds={"slender": 30, "average": 24, "heavy": 35})
        )
    with pytest.raises(InputError, match="bmi_sd"):
        load_build_model(_user_model(tmp_path, "g,a,0.1,x\n", bmi_sd=0.0))
    bare = tmp_path / "bare"
    bare.mkdir()
    shutil.copy(tmp_path / "mine.csv", bare / "mine.csv")
    with pytest.raises(InputError, match="metadata file is missing"):
        load_build_model(bare / "mine.csv")


def test_bmi_builds_are_parsed_and_absurd_ones_refused() -> None:
    assert parse_bmi_build("bmi:27.5") == 27.5 and parse_bmi_build("BMI 30") == 30.0
    assert parse_bmi_build("heavy") is None
    with pytest.raises(InputError, match="not a number"):
        parse_bmi_build("bmi:heavy")
    with pytest.raises(InputError, match="outside"):
        parse_bmi_build("bmi:5")
    # the case's setting accepts the same words
    assert parse_build("heavy") == "heavy" and parse_build("BMI 27.5") == "bmi:27.5"
    with pytest.raises(SetupError, match="outside"):
        parse_build("bmi:90")


# ---------------------------------------------------------------- depths
def test_build_scores_of_a_table_with_sds_and_of_one_without() -> None:
    ttable = load_depth_table("ttable_2023")
    model, z, label = build_score(ttable, "heavy")
    assert model is not None and z == pytest.approx(model.z("heavy")) and "BMI 34" in label
    model, z, label = build_score(ttable, "bmi:28")
    assert model is not None and z == pytest.approx(model.z_of_bmi(28.0)) and "BMI 28" in label
    model, z, label = build_score(ttable, "normal")
    assert model is not None and z == 0.0 and label == ""  # the means, still varied by build
    assert build_score(ttable, 1.5) == (None, 0.0, "")  # uniform mean + k SD: no model
    rhine = load_depth_table("rhine_1983_sw_native_american")
    assert build_score(rhine, "normal") == (None, 0.0, "")
    with pytest.raises(InputError, match="no standard deviations"):
        build_score(rhine, "heavy")


def test_a_heavy_build_thickens_the_cheeks_far_more_than_the_forehead(head_male) -> None:
    from workbench.services.templates.reference_parts import skull_surface

    skull = skull_surface(head_male)
    lms = head_male.skull_landmarks
    mean = plan_dowels(skull, lms, DepthSettings(build="normal", interpolate=False))
    heavy = plan_dowels(skull, lms, DepthSettings(build="heavy", interpolate=False))
    slender = plan_dowels(skull, lms, DepthSettings(build="slender", interpolate=False))
    model = load_build_model()
    z = model.z("heavy")
    assert heavy.build_model and heavy.build_z == pytest.approx(z)
    assert "heavy build (BMI 34" in heavy.group_label
    for code, sd in (("g", 1.0), ("zy_l", 3.0), ("go_r", 6.0)):
        gain = heavy[code].depth_mm - mean[code].depth_mm
        assert gain == pytest.approx(model.loading(code) * sd * z, abs=1e-9)
        assert heavy[code].per_z_mm == pytest.approx(model.loading(code) * sd)
        assert slender[code].depth_mm < mean[code].depth_mm
    assert heavy["go_r"].depth_mm - mean["go_r"].depth_mm > 8 * (
        heavy["g"].depth_mm - mean["g"].depth_mm
    )
    # the uniform variant keeps its meaning: mean + k SD everywhere
    k1 = plan_dowels(skull, lms, DepthSettings(build=1.0, interpolate=False))
    assert not k1.build_model
    assert k1["g"].depth_mm - mean["g"].depth_mm == pytest.approx(1.0)
    assert k1["go_r"].depth_mm - mean["go_r"].depth_mm == pytest.approx(6.0)


# ---------------------------------------------------------------- faces and band
@pytest.fixture(scope="module")
def job(tmp_path_factory: pytest.TempPathFactory, head_female):
    from workbench.io.meshes import write_mesh
    from workbench.services.reconstruction.job import JobSettings, run_reconstruction
    from workbench.services.templates.reference_parts import skull_surface

    path = write_mesh(tmp_path_factory.mktemp("builds") / "skull.ply", skull_surface(head_female))
    return run_reconstruction(path, JobSettings(sex="male", orientation=ORIENT))


@pytest.mark.slow
def test_three_faces_move_along_the_normals_by_build_and_stay_off_the_bone(job) -> None:
    from workbench.core.spatial import MeshIndex

    b = job.fit.builds
    assert b is not None and b.names == BUILD_FACES and b.main == "average"
    np.testing.assert_allclose(b.vertices("average"), job.recon.head.skin.vertices, atol=1e-12)
    np.testing.assert_allclose(b.face("average", job.recon).vertices, job.recon.face.vertices)
    heavy, slender = b.offsets["heavy"], b.offsets["slender"]
    face = np.asarray(job.template.regions["face"])
    assert np.median(heavy[face]) > 2.0 and np.median(slender[face]) < -1.0
    assert (heavy >= -1e-9).all() and (slender <= 1e-9).all()
    # the cheeks gain more than the forehead (the model's regional pattern reaches the skin)
    from workbench.services.templates.regions import face_regions

    regions = face_regions(job.template)
    cheeks, forehead = np.asarray(regions["cheeks"]), np.asarray(regions["forehead"])
    assert np.median(heavy[cheeks]) > 2 * np.median(heavy[forehead])
    # a slender face never goes closer to the bone than the fit's minimum tissue (or than the
    # main face already was)
    d_main = MeshIndex(job.skull_h).signed_distance(job.recon.head.skin.vertices)
    d_thin = MeshIndex(job.skull_h).signed_distance(b.vertices("slender"))
    near = np.abs(d_main) < 30
    assert (d_thin[near] >= np.minimum(d_main[near], 2.0) - 0.3).all()
    # a build between two faces is their blend
    mid = 0.5 * (b.z["average"] + b.z["heavy"])
    np.testing.assert_allclose(
        b.vertices_at(mid), 0.5 * (b.vertices("average") + b.vertices("heavy")), atol=1e-9
    )


@pytest.mark.slow
def test_the_band_spans_the_builds_and_its_coverage_is_measured(job) -> None:
    from workbench.services.reconstruction.build_faces import BAND_Z, MODEL_SD_MM, band_coverage

    b = job.fit.builds
    lower, upper = b.band()
    assert (lower <= b.offsets["slender"] + 1e-9).all()  # the floor never passes a face
    assert (upper >= b.offsets["heavy"] + BAND_Z * MODEL_SD_MM - 1e-6).all()
    assert (b.half_width_mm > BAND_Z * MODEL_SD_MM - 1e-6).all()
    lo_k, hi_k = b.band("heavy")
    assert np.median(hi_k - lo_k) < np.median(upper - lower)  # a known build: narrower
    # coverage: points on the heavy face are inside the unknown-build band and the heavy
    # band
    face = job.recon.face
    heavy_face = b.face("heavy", job.recon)
    ids = np.asarray(job.template.regions["face"])[::7]
    pts = heavy_face.vertices[ids]
    # (a point's closest place on the main face is not always its own vertex: ~96 %)
    assert band_coverage(face, lower, upper, pts)["coverage"] > 0.95
    assert band_coverage(face, lo_k, hi_k, pts)["coverage"] > 0.95


def test_band_coverage_counts_points_between_the_edges_along_the_outward_side() -> None:
    from workbench.core.mesh import Mesh
    from workbench.services.reconstruction.build_faces import band_coverage

    g = np.linspace(-50, 50, 21)
    x, y = np.meshgrid(g, g)
    v = np.column_stack([x.ravel(), y.ravel(), np.zeros(x.size)])
    f = []
    for i in range(20):
        for j in range(20):
            a = i * 21 + j
            f += [[a, a + 1, a + 22], [a, a + 22, a + 21]]
    plane = Mesh(v, np.array(f))  # outward = +z
    assert plane.face_normals[0, 2] > 0
    n = len(v)
    lower, upper = np.full(n, -1.0), np.full(n, 2.0)
    rng = np.random.default_rng(0)
    xy = rng.uniform(-40, 40, (400, 2))
    z = np.repeat([-0.5, 1.5, -2.0, 3.0], 100)  # inside, inside, too deep, too far out
    pts = np.column_stack([xy, z])
    labels = np.repeat([0, 1], 200)
    out = band_coverage(plane, lower, upper, pts, labels, ("inside", "outside"))
    assert out["coverage"] == pytest.approx(0.5)
    assert out["half_width_median_mm"] == pytest.approx(1.5)
    assert out["regions"]["inside"]["coverage"] == 1.0
    assert out["regions"]["outside"]["coverage"] == 0.0


@pytest.mark.slow
def test_the_job_writes_the_faces_the_band_and_the_morph_targets(job, tmp_path: Path) -> None:
    import pygltflib

    from workbench.io.meshes import read_mesh
    from workbench.services.reconstruction.job import write_outputs

    files = write_outputs(job, tmp_path / "out")
    out = tmp_path / "out"
    b = job.fit.builds
    for name in BUILD_FACES:
        mesh = read_mesh(out / f"face_{name}.ply").mesh
        np.testing.assert_allclose(mesh.vertices, b.face(name, job.recon).vertices, atol=1e-6)
    band = np.load(out / "face_band_mm.npy")
    np.testing.assert_allclose(band, b.half_width_mm, rtol=1e-5)
    edges = np.load(out / "face_band_edges_mm.npy")
    assert edges.shape == (len(band), 2) and (edges[:, 0] < edges[:, 1]).all()
    header = (out / "face.ply").read_bytes()[:2000]
    assert b"property float band_mm" in header
    np.testing.assert_allclose(read_mesh(out / "face.ply").mesh.vertices, job.recon.face.vertices)
    glb = pygltflib.GLTF2().load(str(files["builds_glb"]))
    names = glb.meshes[0].extras.get("targetNames")
    assert names == ["slender", "heavy"]
    assert job.report["builds"]["main"] == "average"
    assert set(job.report["builds"]["builds"]) == set(BUILD_FACES)


def test_a_build_the_table_cannot_vary_gives_one_face_with_a_note(head_male) -> None:
    from workbench.services.reconstruction.build_faces import build_faces
    from workbench.services.reconstruction.reconstruct import Reconstruction
    from workbench.services.templates.reference_parts import skull_surface

    plan = plan_dowels(
        skull_surface(head_male), head_male.skull_landmarks, DepthSettings(build=2.0)
    )
    recon = Reconstruction(
        head_male, np.eye(4), False, plan, np.zeros((0, 3)), np.zeros((0, 3)), {}
    )
    assert build_faces(recon, load_build_model()) is None
