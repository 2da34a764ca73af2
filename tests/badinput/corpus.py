"""The bad-input corpus: one entry per bad file or value, grouped by family (issue 12).

Families
--------
A  absurd values that used to be reported as success (bounds, lengths in mm)
B  inputs that used to end in "unexpected error" (NaN, inf, folders, no overlap)
C  misleading messages (landmarks off the skull, wrong units, broken meshes)
D  units (``--units`` with ``--scale``)
O  other bad files (empty, wrong extension, garbage, bad tables and landmark files)

``argv`` items in braces name files made by ``_files.make_bad_files``;
``{out}`` is a not-yet-existing folder in the test's tmp_path.  Every entry
must fail fast (before any fit) with exit status != 0 and a message holding
each of ``expect`` (case-insensitive) and ``names`` (the file or option).
"""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class Entry:
    id: str
    family: str
    argv: tuple[str, ...]
    expect: tuple[str, ...]
    names: str


def _e(id_: str, family: str, argv: str, expect: str | tuple[str, ...], names: str) -> Entry:
    return Entry(
        id_,
        family,
        tuple(argv.split()),
        (expect,) if isinstance(expect, str) else tuple(expect),
        names,
    )


R = "reconstruct {skull} --no-pictures --out {out}"
CT = "mesh-from-ct {ct_good} --out {out}.ply --quiet"

ENTRIES: tuple[Entry, ...] = (
    # fit-scan (issue 13): scans that are not one face's surface, in the units given
    _e(
        "scan_point_cloud",
        "O",
        "fit-scan {point_cloud} --units mm --out {out}",
        "point cloud",
        "point_cloud.ply",
    ),
    _e(
        "scan_two_heads",
        "O",
        "fit-scan {two_heads} --units mm --out {out}",
        ("2 separate surfaces", "two heads"),
        "two_heads.ply",
    ),
    _e(
        "scan_few_triangles",
        "O",
        "fit-scan {two_triangles} --units mm --out {out}",
        "only 2 triangles",
        "two_triangles.ply",
    ),
    _e(
        "scan_mm_read_as_m",
        "D",
        "fit-scan {skin} --units m --out {out}",
        ("largest side", "--units"),
        "skin.ply",
    ),
    # ---------------------------------------------------------------- A: absurd values
    _e("table_depth_5500mm", "A", R + " --table {table_5500}", ("5500", "60 mm"), "table_5500.csv"),
    _e("table_depth_zero", "A", R + " --table {table_zero}", "mean_mm", "table_zero.csv"),
    _e(
        "table_sd_900mm", "A", R + " --table {table_huge_sd}", ("sd_mm", "900"), "table_huge_sd.csv"
    ),
    _e("override_1e6", "A", R + " --override g=1e6", ("1000000", "60"), "--override"),
    _e("override_negative", "A", R + " --override g=-3", "-3", "--override"),
    _e("override_nan", "A", R + " --override g=nan", "nan", "--override"),
    _e("override_not_number", "A", R + " --override g=deep", "CODE=MM", "--override"),
    _e("build_99", "A", R + " --build 99", ("99", "4 SD"), "--build"),
    _e("build_minus_1e9", "A", R + " --build=-1e9", ("-1e9", "4 SD"), "--build"),
    _e("build_inf", "A", R + " --build inf", "finite", "--build"),
    _e("build_bmi_5", "A", R + " --build bmi:5", ("BMI 5", "12-70"), "--build"),
    _e("build_bmi_word", "A", R + " --build bmi:heavy", "bmi:heavy", "--build"),
    _e("ensemble_1e8", "A", R + " --ensemble 100000000", ("100000000", "500"), "--ensemble"),
    _e("ensemble_negative", "A", R + " --ensemble -3", "-3", "--ensemble"),
    _e(
        "flat_skull",
        "A",
        "reconstruct {flat_skull} --no-pictures --out {out}",
        ("flat", "mm"),
        "flat_skull.ply",
    ),
    _e(
        "line_skull",
        "A",
        "reconstruct {line_skull} --no-pictures --out {out}",
        ("flat", "mm"),
        "line_skull.ply",
    ),
    _e(
        "collinear_landmarks",
        "A",
        R + " --landmarks {landmarks_collinear}",
        "line",
        "collinear.mrk.json",
    ),
    _e(
        "nifti_voxel_0",
        "A",
        "mesh-from-ct {ct_voxel0} --out {out}.ply --quiet",
        ("voxel size", "0"),
        "ct_voxel0.nii",
    ),
    _e(
        "nifti_voxel_3km",
        "A",
        "mesh-from-ct {ct_km} --out {out}.ply --quiet",
        ("voxel size", "3.2e+06"),
        "ct_km.nii",
    ),
    _e(
        "target_triangles_0", "A", CT + " --target-triangles 0", ("0", "1000"), "--target-triangles"
    ),
    _e(
        "target_triangles_1e10",
        "A",
        CT + " --target-triangles 10000000000",
        ("10000000000", "5000000"),
        "--target-triangles",
    ),
    _e("smooth_negative", "A", CT + " --smooth -1", "-1", "--smooth"),
    _e("smooth_1e6", "A", CT + " --smooth 1000000", ("1000000", "500"), "--smooth"),
    _e("iso_nan", "A", CT + " --iso nan", "nan", "--iso"),
    _e("scale_zero", "A", "mesh info {skull} --scale 0", "positive", "--scale"),
    _e("scale_negative", "A", "reconstruct {skull} --scale -2 --out {out}", "positive", "--scale"),
    _e("scale_nan", "A", "case new {skull} --scale nan --out {out}.fcase", "positive", "--scale"),
    _e(
        "compare_max_distance_negative",
        "A",
        "compare {skin} {skin} --region all --max-distance -1",
        "-1",
        "--max-distance",
    ),
    _e("compare_clim_zero", "A", "compare {skin} {skin} --region all --clim 0", "0", "--clim"),
    # ---------------------------------------------------------------- B: unexpected errors
    _e(
        "nan_skull_reconstruct",
        "B",
        "reconstruct {nan_skull} --out {out}",
        ("3 vertices", "nan"),
        "nan_skull.ply",
    ),
    _e(
        "inf_skull_reconstruct",
        "B",
        "reconstruct {inf_skull} --out {out}",
        ("1 vertices", "infinite"),
        "inf_skull.ply",
    ),
    _e(
        "nan_skull_suggest",
        "B",
        "landmarks suggest {nan_skull} --out {out}.mrk.json",
        ("3 vertices", "nan"),
        "nan_skull.ply",
    ),
    _e(
        "nan_skull_template_build",
        "B",
        "template build --skin {skin} --skull {nan_skull} --out {out}",
        ("3 vertices", "nan"),
        "nan_skull.ply",
    ),
    _e(
        "nan_recon_compare",
        "B",
        "compare {nan_skull} {skin} --region all",
        ("3 vertices", "nan"),
        "nan_skull.ply",
    ),
    _e(
        "nan_truth_compare",
        "B",
        "compare {skin} {nan_skin} --region all",
        ("1 vertices", "nan"),
        "nan_skin.ply",
    ),
    _e(
        "nan_skull_case_new",
        "B",
        "case new {nan_skull} --out {out}.fcase",
        ("3 vertices", "nan"),
        "nan_skull.ply",
    ),
    _e(
        "nan_mesh_convert",
        "B",
        "mesh convert {nan_skull} {out}.stl",
        ("3 vertices", "nan"),
        "nan_skull.ply",
    ),
    _e(
        "nan_voxels",
        "B",
        "mesh-from-ct {ct_nan_voxels} --out {out}.ply --quiet",
        ("27 voxels", "nan"),
        "ct_nan_voxels.nii",
    ),
    _e(
        "nan_spacing",
        "B",
        "mesh-from-ct {ct_nan_spacing} --out {out}.ply --quiet",
        ("voxel", "nan"),
        "ct_nan_spacing.nii",
    ),
    _e("target_triangles_negative", "B", CT + " --target-triangles -5", "-5", "--target-triangles"),
    _e("guides_nonsense", "B", R + " --guides nonsense", "cannot read", "nonsense"),
    _e("guides_not_json", "B", R + " --guides {guides_garbage}", "json", "guides.json"),
    _e("axes_parallel", "B", R + " --anterior 0,0,1 --superior 0,0,2", "parallel", "--anterior"),
    _e("axes_zero", "B", R + " --anterior 0,0,0 --superior 0,1,0", "zero", "--anterior"),
    _e("axes_one_only", "B", R + " --anterior 0,0,1", "both", "--anterior"),
    _e(
        "porions_coincide_frame",
        "B",
        "landmarks frame {porions_same} --surface skull",
        "porion",
        "porions_same.mrk.json",
    ),
    _e(
        "porions_coincide_reconstruct",
        "B",
        R + " --landmarks {porions_same}",
        "porion",
        "porions_same.mrk.json",
    ),
    _e(
        "out_is_a_file_reconstruct",
        "B",
        "reconstruct {skull} --out {not_a_file_out}",
        "not a folder",
        "regular_file",
    ),
    _e(
        "out_unwritable_reconstruct",
        "B",
        "reconstruct {skull} --out {not_a_file_out}/sub",
        "cannot",
        "regular_file",
    ),
    _e(
        "out_is_a_file_template_build",
        "B",
        "template build --skin {skin} --skull {skull} --out {not_a_file_out}",
        "not a folder",
        "regular_file",
    ),
    _e(
        "out_unwritable_mesh_from_ct",
        "B",
        "mesh-from-ct {ct_good} --out {not_a_file_out}/b.ply --quiet",
        "cannot",
        "regular_file",
    ),
    _e(
        "out_unwritable_compare",
        "B",
        "compare {skin} {skin} --region all --out {not_a_file_out}/c",
        "cannot",
        "regular_file",
    ),
    _e(
        "compare_no_overlap",
        "B",
        "compare {skin} {far_skin} --region all",
        ("do not overlap", "nearest distance"),
        "far_skin.ply",
    ),
    # ---------------------------------------------------------------- C: misleading messages
    _e(
        "landmarks_50mm_off",
        "C",
        R + " --landmarks {landmarks_off50}",
        ("8 of 8 skull landmarks", "from the skull surface", "median 50"),
        "off50.mrk.json",
    ),
    _e(
        "landmarks_lps_ras_flipped",
        "C",
        R + " --landmarks {landmarks_flipped}",
        ("skull landmarks are more than", "x and y negated they lie on the skull", "LPS/RAS"),
        "flipped.mrk.json",
    ),
    _e(
        "units_cm_on_mm_skull",
        "C",
        "reconstruct {skull} --units cm --out {out}",
        ("2000 mm", "100-350 mm"),
        "skull.ply",
    ),
    _e(
        "units_m_on_cm_skull",
        "C",
        "reconstruct {skull_cm} --units m --out {out}",
        ("20000 mm", "100-350 mm"),
        "skull_cm.ply",
    ),
    _e(
        "units_cm_suggest",
        "C",
        "landmarks suggest {skull} --units cm --out {out}.mrk.json",
        ("2000 mm", "100-350 mm"),
        "skull.ply",
    ),
    _e(
        "units_cm_case_new",
        "C",
        "case new {skull} --units cm --out {out}.fcase",
        ("2000 mm", "100-350 mm"),
        "skull.ply",
    ),
    _e(
        "two_triangle_skull",
        "C",
        "reconstruct {two_triangles} --out {out}",
        "2 triangles",
        "two_triangles.ply",
    ),
    _e(
        "two_triangle_suggest",
        "C",
        "landmarks suggest {two_triangles} --out {out}.mrk.json",
        "2 triangles",
        "two_triangles.ply",
    ),
    _e(
        "two_triangle_template_build",
        "C",
        "template build --skin {skin} --skull {two_triangles} --out {out}",
        "2 triangles",
        "two_triangles.ply",
    ),
    _e(
        "nonmanifold_skull",
        "C",
        "reconstruct {nonmanifold} --out {out}",
        "non-manifold",
        "nonmanifold.ply",
    ),
    _e(
        "units_auto_cm_skull",
        "C",
        "reconstruct {skull_cm} --out {out}",
        "units unclear",
        "skull_cm.ply",
    ),
    # ---------------------------------------------------------------- D: units
    _e(
        "units_and_scale_reconstruct",
        "D",
        "reconstruct {skull} --units m --scale 10 --out {out}",
        "not both",
        "--units",
    ),
    _e(
        "units_and_scale_info",
        "D",
        "mesh info {skull} --units cm --scale 10",
        "not both",
        "--units",
    ),
    _e(
        "units_and_scale_convert",
        "D",
        "mesh convert {skull} {out}.stl --units cm --scale 10",
        "not both",
        "--units",
    ),
    _e(
        "units_and_scale_suggest",
        "D",
        "landmarks suggest {skull} --units m --scale 3 --out {out}.mrk.json",
        "not both",
        "--units",
    ),
    _e(
        "units_and_scale_case_new",
        "D",
        "case new {skull} --units cm --scale 10 --out {out}.fcase",
        "not both",
        "--units",
    ),
    _e(
        "units_and_scale_template_build",
        "D",
        "template build --skin {skin} --skull {skull} --units cm --scale 10 --out {out}",
        "not both",
        "--units",
    ),
    _e(
        "units_and_scale_compare_truth",
        "D",
        "compare {skin} {skin} --region all --truth-units cm --truth-scale 10",
        "not both",
        "--truth-units",
    ),
    # ---------------------------------------------------------------- O: other bad files
    _e("empty_ply", "O", "mesh info {empty_ply}", "empty", "empty.ply"),
    _e("garbage_ply", "O", "mesh info {garbage_ply}", "ply", "garbage.ply"),
    _e(
        "truncated_ply", "O", "reconstruct {header_only_ply} --out {out}", "vert", "header_only.ply"
    ),
    _e("face_index_out_of_range", "O", "mesh info {bad_index_ply}", "7", "bad_index.ply"),
    _e("wrong_extension", "O", "reconstruct {wrong_ext} --out {out}", "'.txt'", "skull.txt"),
    _e("folder_as_mesh", "O", "reconstruct {folder_ply} --out {out}", "folder", "folder.ply"),
    _e(
        "missing_mesh",
        "O",
        "compare {missing} {skin} --region all",
        "no such file",
        "does_not_exist.ply",
    ),
    _e("missing_truth", "O", R + " --truth {missing}", "no such file", "does_not_exist.ply"),
    _e(
        "missing_template_pack",
        "O",
        R + " --template {missing}",
        "not a template pack",
        "does_not_exist.ply",
    ),
    _e("unknown_rule", "O", R + " --rule no_such_rule", "unknown", "no_such_rule"),
    _e("unknown_exclude", "O", R + " --exclude zzz", "unknown", "zzz"),
    _e(
        "landmarks_unknown_code",
        "O",
        R + " --landmarks {landmarks_unknown}",
        "zz_not_a_code",
        "unknown.mrk.json",
    ),
    _e(
        "landmarks_duplicate_code",
        "O",
        R + " --landmarks {landmarks_duplicate}",
        "duplicate",
        "duplicate.mrk.json",
    ),
    _e(
        "landmarks_partial_nan",
        "O",
        R + " --landmarks {landmarks_partial_nan}",
        ("'g'", "partly missing"),
        "partial_nan.csv",
    ),
    _e(
        "landmarks_empty_file", "O", R + " --landmarks {landmarks_empty}", "empty", "empty.mrk.json"
    ),
    _e(
        "landmarks_not_json",
        "O",
        "landmarks check {landmarks_garbage} --surface skull",
        "json",
        "garbage.mrk.json",
    ),
    _e(
        "landmarks_wrong_extension",
        "O",
        "landmarks check {landmarks_wrong_ext} --surface skull",
        ".docx",
        "points.docx",
    ),
    _e(
        "landmarks_missing",
        "O",
        R + " --landmarks {missing_landmarks}",
        "not found",
        "does_not_exist.mrk.json",
    ),
    _e(
        "table_missing_columns",
        "O",
        R + " --table {table_missing_columns}",
        "missing columns",
        "table_missing.csv",
    ),
    _e(
        "table_negative_sd",
        "O",
        R + " --table {table_negative_sd}",
        "sd_mm",
        "table_negative_sd.csv",
    ),
    _e("table_unknown_code", "O", R + " --table {table_unknown_code}", "zorg", "table_unknown.csv"),
    _e(
        "table_duplicate_row",
        "O",
        R + " --table {table_duplicate}",
        "duplicate",
        "table_duplicate.csv",
    ),
    _e(
        "table_text_depth", "O", R + " --table {table_text_depth}", "not a number", "table_text.csv"
    ),
    _e("table_empty_file", "O", R + " --table {table_empty}", "missing columns", "table_empty.csv"),
    _e("table_nan_depth", "O", R + " --table {table_nan}", "mean_mm", "table_nan.csv"),
    _e(
        "table_unknown_id",
        "O",
        R + " --table no_such_table",
        "unknown tissue-depth table",
        "no_such_table",
    ),
    _e(
        "ct_garbage",
        "O",
        "mesh-from-ct {ct_garbage} --out {out}.ply --quiet",
        "nifti",
        "ct_garbage.nii.gz",
    ),
    _e("ct_empty", "O", "mesh-from-ct {ct_empty} --out {out}.ply --quiet", "", "ct_empty.nrrd"),
    _e(
        "ct_missing",
        "O",
        "mesh-from-ct {missing} --out {out}.ply --quiet",
        "no such file",
        "does_not_exist.ply",
    ),
    _e("case_info_not_a_case", "O", "case info {garbage_ply}", "case", "garbage.ply"),
    _e("snap_not_a_case", "O", "landmarks snap {skull} --all --dry-run", "damaged", "skull.ply"),
    _e("convert_unsupported_out", "O", "mesh convert {skull} {out}.xyz", "'.xyz'", ".xyz"),
    # age (issue 15): ages the norms do not cover, unknown populations, tables without SDs
    _e(
        "age_outside_norms",
        "A",
        "age reference:male --sex male --from 18 --to 60 --out {out}",
        "outside the norms' range",
        "--to",
    ),
    _e(
        "age_negative",
        "A",
        "age reference:male --sex male --from -3 --to 8 --out {out}",
        "not an age",
        "--from",
    ),
    _e(
        "age_unknown_ethnicity",
        "O",
        "age reference:female --sex female --from 18 --to 8 --ethnicity Martian --out {out}",
        "has no norms",
        "--ethnicity",
    ),
    _e(
        "age_norms_without_sd",
        "O",
        "age reference:male --sex male --from 18 --to 8 --norms {norms_no_sd} --out {out}",
        "sd",
        "norms_no_sd.csv",
    ),
    _e(
        "age_ages_not_numbers",
        "O",
        "age reference:male --sex male --from 18 --ages 3,x --out {out}",
        "not a number",
        "--ages",
    ),
    _e(
        "age_head_not_a_pack",
        "O",
        "age {folder_ply} --sex male --from 18 --to 8 --out {out}",
        "neither a template pack",
        "folder.ply",
    ),
)


def by_family() -> dict[str, int]:
    """Number of entries per family."""
    counts: dict[str, int] = {}
    for e in ENTRIES:
        counts[e.family] = counts.get(e.family, 0) + 1
    return counts
