"""Landmark exchange formats: exact round trips, LPS/RAS handling, problems reported by name."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from workbench.core.errors import InputError, LandmarkError
from workbench.core.landmarks import Landmark, LandmarkSet
from workbench.io.markups import (
    read_csv,
    read_fcsv,
    read_landmarks,
    read_mrk_json,
    read_pp,
    write_csv,
    write_fcsv,
    write_landmarks,
    write_mrk_json,
    write_pp,
)

EXTENSIONS = [".mrk.json", ".json", ".fcsv", ".pp", ".csv"]
NAN3 = [np.nan] * 3


@pytest.fixture
def sample() -> LandmarkSet:
    """Left/right points (subject's left = +x in RAS), a suggestion, undefined points."""
    return LandmarkSet(
        "skin",
        (
            Landmark("ex_l", [45.25, 61.0, 12.125]),
            Landmark("ex_r", [-44.75, 60.5, 12.0], description="right eye, outer corner"),
            Landmark(
                "prn",
                [0.1, 98.30000000000001, -20.7],
                "suggested",
                0.35,
                'tip, "estimated"\nfrom Rynn; Ünïcode',
            ),
            Landmark("go_l", NAN3, "absent", description="mandible broken"),
            Landmark("go_r", NAN3, "missing"),
            Landmark("ch_r", [-25.0, 80.0, -45.0], description="a\r\nb,c"),
        ),
    )


@pytest.mark.parametrize("ext", EXTENSIONS)
def test_round_trip_exact(tmp_path, sample, ext):
    path = tmp_path / f"points{ext}"
    write_landmarks(path, sample)
    result = read_landmarks(path, "skin", allow_undefined=True)
    assert result.landmarks.equals(sample), result.landmarks
    assert result.unknown == () and result.duplicates == ()
    assert result.undefined == ("go_l", "go_r")


@pytest.mark.parametrize("ext", EXTENSIONS)
def test_undefined_skipped_by_default_and_named(tmp_path, sample, ext):
    path = tmp_path / f"points{ext}"
    write_landmarks(path, sample)
    result = read_landmarks(path, "skin")
    assert result.landmarks.codes == ("ex_l", "ex_r", "prn", "ch_r")
    assert result.undefined == ("go_l", "go_r")
    assert any("go_l" in m and "go_r" in m for m in result.messages)
    with pytest.raises(LandmarkError, match="go_l"):
        read_landmarks(path, "skin", strict=True)
    assert read_landmarks(path, "skin", strict=True, allow_undefined=True).landmarks.equals(sample)


@pytest.mark.parametrize(
    "writer,reader", [(write_mrk_json, read_mrk_json), (write_fcsv, read_fcsv)]
)
@pytest.mark.parametrize("cs", ["LPS", "RAS"])
def test_slicer_formats_in_both_frames(tmp_path, sample, writer, reader, cs):
    path = tmp_path / ("p.mrk.json" if writer is write_mrk_json else "p.fcsv")
    writer(path, sample, coordinate_system=cs)
    result = reader(path, "skin", allow_undefined=True)
    assert result.coordinate_system == cs
    assert result.landmarks.equals(sample)


def test_lps_file_stores_flipped_numbers(tmp_path, sample):
    path = tmp_path / "p.mrk.json"
    write_mrk_json(path, sample)  # default LPS
    doc = json.loads(path.read_text(encoding="utf-8"))
    mk = doc["markups"][0]
    assert mk["coordinateSystem"] == "LPS" and mk["type"] == "Fiducial"
    stored = {cp["label"]: cp for cp in mk["controlPoints"]}
    assert stored["ex_l"]["position"] == [-45.25, -61.0, 12.125]
    assert stored["go_l"]["positionStatus"] == "missing" and stored["go_l"]["position"] == ""
    assert stored["prn"]["description"].startswith("tip")
    assert stored["prn"]["description"].endswith("[workbench: suggested; confidence 0.35]")
    fcsv = tmp_path / "p.fcsv"
    write_fcsv(fcsv, sample)
    lines = fcsv.read_text(encoding="utf-8").splitlines()
    assert lines[1] == "# CoordinateSystem = LPS"
    assert lines[3].split(",")[1:4] == ["-45.25", "-61.0", "12.125"]
    # reading gives RAS back: the subject's left eye stays at +x (no mirror)
    assert read_mrk_json(path, "skin").landmarks["ex_l"].position[0] == 45.25


def _mrk(cs: str, points: list[tuple[str, list[float], str]]) -> dict:
    return {
        "@schema": "https://example/markups-schema-v1.0.3.json#",
        "markups": [
            {
                "type": "Fiducial",
                "coordinateSystem": cs,
                "controlPoints": [
                    {"label": lab, "position": pos, "positionStatus": state}
                    for lab, pos, state in points
                ],
            }
        ],
    }


def test_hand_written_ras_and_lps_files_agree(tmp_path):
    ras = [
        ("Lex", [31.5, 20.0, 5.0], "defined"),
        ("Rex", [-30.0, 19.5, 5.25], "defined"),
        ("prn", [0.0, 55.0, -10.0], "defined"),
    ]
    lps = [(lab, [-x, -y, z], state) for lab, (x, y, z), state in ras]
    (tmp_path / "ras.mrk.json").write_text(json.dumps(_mrk("RAS", ras)), encoding="utf-8")
    (tmp_path / "lps.mrk.json").write_text(json.dumps(_mrk("LPS", lps)), encoding="utf-8")
    a = read_landmarks(tmp_path / "ras.mrk.json", "skin").landmarks
    b = read_landmarks(tmp_path / "lps.mrk.json", "skin").landmarks
    assert a.codes == ("ex_l", "ex_r", "prn") and a.equals(b)
    assert a["ex_l"].position.tolist() == [31.5, 20.0, 5.0]
    header = "# Markups fiducial file version = 4.10\n# CoordinateSystem = {}\n"
    for flag, rows in (("0", ras), ("1", lps), ("RAS", ras), ("LPS", lps)):
        body = "".join(
            f"vtkMRMLMarkupsFiducialNode_{i},{p[0]},{p[1]},{p[2]},0,0,0,1,1,1,0,{lab},,\n"
            for i, (lab, p, _) in enumerate(rows)
        )
        (tmp_path / "f.fcsv").write_text(header.format(flag) + body, encoding="utf-8")
        assert read_fcsv(tmp_path / "f.fcsv", "skin").landmarks.equals(a), flag


def test_unknown_duplicate_undefined_reported_by_name(tmp_path):
    doc = _mrk(
        "RAS",
        [
            ("exL", [1.0, 2.0, 3.0], "defined"),
            ("ex_l", [9.0, 9.0, 9.0], "defined"),
            ("foo", [0.0, 0.0, 0.0], "defined"),
            ("prn", [0.0, 0.0, 0.0], "undefined"),
            ("sn", [0.0, 50.0, -20.0], "preview"),
        ],
    )
    path = tmp_path / "mixed.mrk.json"
    path.write_text(json.dumps(doc), encoding="utf-8")
    r = read_mrk_json(path, "skin")
    assert r.landmarks.codes == ("ex_l",) and r.landmarks["ex_l"].position.tolist() == [
        1.0,
        2.0,
        3.0,
    ]
    assert (r.unknown, r.duplicates, r.undefined) == (("foo",), ("ex_l",), ("prn", "sn"))
    text = " ".join(r.messages)
    assert "foo" in text and "ex_l" in text and "prn" in text
    with pytest.raises(LandmarkError) as err:
        read_mrk_json(path, "skin", strict=True)
    assert all(name in str(err.value) for name in ("foo", "ex_l", "prn", "sn"))
    kept = read_mrk_json(path, "skin", allow_undefined=True).landmarks
    assert kept["prn"].status == "missing" and np.isnan(kept["prn"].position).all()
    assert kept["sn"].status == "suggested" and kept["sn"].position.tolist() == [0.0, 50.0, -20.0]


def test_meshlab_file(tmp_path):
    text = (
        "<!DOCTYPE PickedPoints>\n<PickedPoints>\n <DocumentData>\n"
        '  <DateTime time="10:00:00" date="2024-01-01"/>\n  <User name="x"/>\n'
        '  <DataFileName name="skull.ply"/>\n  <templateName name=""/>\n </DocumentData>\n'
        ' <point x="1.5" y="-2" z="3e1" active="1" name="zyL"/>\n'
        ' <point x="0" y="0" z="0" active="0" name="zyR"/>\n'
        ' <point x="4" y="5" z="6" active="1" name="3"/>\n</PickedPoints>\n'
    )
    path = tmp_path / "skull.pp"
    path.write_text(text, encoding="utf-8")
    r = read_pp(path, "skull")
    assert r.landmarks.codes == ("zy_l",) and r.landmarks["zy_l"].position.tolist() == [
        1.5,
        -2.0,
        30.0,
    ]
    assert r.undefined == ("zyR",) and r.unknown == ("3",)


def test_real_fiducials_csv(tmp_path, shared_data):
    """MNE fsaverage fiducials: nasion resolves, LPA/RPA are not catalogue points."""
    src = shared_data / "fsaverage_head_mne" / "fsaverage-fiducials_mm.csv"
    r = read_csv(src, "skin")
    assert r.landmarks.codes == ("n",)
    assert r.landmarks["n"].position.tolist() == [1.468, 85.067, -34.836]
    assert r.unknown == ("LPA", "RPA")
    with pytest.raises(LandmarkError, match="LPA"):
        read_csv(src, "skin", strict=True)
    for ext in EXTENSIONS:
        write_landmarks(tmp_path / f"n{ext}", r.landmarks)
        assert read_landmarks(tmp_path / f"n{ext}", "skin").landmarks.equals(r.landmarks)


def test_csv_header_states_units_and_frame(tmp_path, sample):
    write_csv(tmp_path / "p.csv", sample, frame="head frame (FH)")
    first, second = (tmp_path / "p.csv").read_text(encoding="utf-8").splitlines()[:2]
    assert first.startswith("# units: mm; frame: head frame (FH)")
    assert second == "code,x_mm,y_mm,z_mm,status,confidence,description"


def test_pp_keeps_mesh_coordinates(tmp_path, sample):
    write_pp(tmp_path / "p.pp", sample, mesh_file="head.ply")
    text = (tmp_path / "p.pp").read_text(encoding="utf-8")
    assert text.startswith("<!DOCTYPE PickedPoints>")
    assert 'x="45.25"' in text and 'name="head.ply"' in text


@pytest.mark.parametrize(
    "name,content,problem",
    [
        (
            "cut.mrk.json",
            '{"@schema": "x", "markups": [{"type": "Fiducial", "controlPoints": [{"lab',
            "not valid JSON",
        ),
        ("other.json", '{"hello": 1}', "no 'markups' list"),
        ("lines.mrk.json", '{"markups": [{"type": "Line", "controlPoints": []}]}', "no point list"),
        (
            "badpos.mrk.json",
            '{"markups": [{"type": "Fiducial", "controlPoints": [{"label": "n", '
            '"position": [1, "x", 3]}]}]}',
            "expected a finite number",
        ),
        (
            "frame.mrk.json",
            '{"markups": [{"type": "Fiducial", "coordinateSystem": "IJK"}]}',
            "coordinate system",
        ),
        (
            "broken.pp",
            "<PickedPoints><point x='1' y='2' z='3' name='n'></PickedPoints>",
            "broken XML",
        ),
        ("wrong.pp", "<Scene/>", "not a MeshLab"),
        (
            "text.fcsv",
            "# CoordinateSystem = LPS\nid,one,two,three,0,0,0,1,1,1,0,n,,\n",
            "expected a finite number",
        ),
        (
            "nan.fcsv",
            "# CoordinateSystem = RAS\nid,1,inf,3,0,0,0,1,1,1,0,n,,\n",
            "expected a finite number",
        ),
        ("cm.csv", "# units: cm; frame: x\ncode,x_mm,y_mm,z_mm\nn,1,2,3\n", "'cm'"),
        ("cols.csv", "code,a,b,c\nn,1,2,3\n", "x_mm"),
        ("status.csv", "code,x_mm,y_mm,z_mm,status\nn,1,2,3,maybe\n", "unknown status"),
        ("points.xyz", "1 2 3\n", "unknown landmark file type"),
    ],
)
def test_corrupt_files_raise_input_error(tmp_path, name, content, problem):
    path = tmp_path / name
    path.write_text(content, encoding="utf-8")
    with pytest.raises(InputError, match=problem) as err:
        read_landmarks(path, "skin")
    assert str(path) in str(err.value)


def test_binary_and_missing_files(tmp_path):
    (tmp_path / "bin.fcsv").write_bytes(b"\xff\xfe\x00\x81garbage")
    with pytest.raises(InputError, match="bin.fcsv"):
        read_fcsv(tmp_path / "bin.fcsv", "skin")
    with pytest.raises(InputError, match="not found"):
        read_landmarks(tmp_path / "nothing.mrk.json", "skin")


def test_surface_mismatch_is_noted(tmp_path):
    skull = LandmarkSet("skull", (Landmark("n", [0.0, 90.0, 0.0]),))
    write_mrk_json(tmp_path / "s.mrk.json", skull)
    r = read_mrk_json(tmp_path / "s.mrk.json", "skin")
    assert any("skull landmarks" in m for m in r.messages)


finite = st.floats(allow_nan=False, allow_infinity=False, width=64)


@settings(
    max_examples=40, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture]
)
@given(
    xyz=st.lists(st.tuples(finite, finite, finite), min_size=2, max_size=2),
    conf=st.floats(0.0, 1.0),
    text=st.text(max_size=20),
)
def test_any_float_round_trips(tmp_path_factory, xyz, conf, text):
    lms = LandmarkSet(
        "skull", (Landmark("zy_l", xyz[0], "suggested", conf, text), Landmark("zy_r", xyz[1]))
    )
    folder = tmp_path_factory.mktemp("prop")
    for ext in EXTENSIONS:
        path = Path(folder) / f"p{ext}"
        write_landmarks(path, lms)
        back = read_landmarks(path, "skull").landmarks
        assert back.equals(lms), (ext, back)
