"""The automatic registration on a fixed subset of the robustness corpus (issue 28).

Real bone: headsq's CT, remade as other programs and scanners would give it —
another iso level, every piece kept, turned, mirrored and in cm, with its jaw
opened, detached or missing, pins, a CT table and a head holder beside it —
registered with no orientation and no landmarks, and judged against the
base's hinted registration carried through the same transforms
(``benchmarks/corpus``).  The VHP cases run in ``benchmarks/bench_robustness.py``
(minutes each in a test run).  Meshes are built into a temporary folder from
the real CT, never committed.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

REPO = Path(__file__).resolve().parents[2]
if str(REPO) not in sys.path:
    sys.path.insert(0, str(REPO))

from benchmarks.corpus import common, evaluate, truth, variants  # noqa: E402

pytestmark = pytest.mark.slow


def _spec(index: int, **changes) -> variants.VariantSpec:
    """headsq at its multi-Otsu level, every piece, in mm, unmirrored, but for ``changes``."""
    plain = dict(iso="otsu", mirror_axis=-1, units="mm")
    return variants.plain_spec("headsq", index=index, **(plain | changes))


def _axes(seed: int) -> dict:
    rng = np.random.default_rng(seed)
    rot = common.rotation_matrix(rng.normal(size=3), float(rng.uniform(40.0, 170.0)))
    return {
        "axes": "random",
        "rotation": tuple(tuple(row) for row in rot),
        "translation": tuple(rng.uniform(-400.0, 400.0, 3)),
    }


def _scored(spec: variants.VariantSpec, root: Path) -> tuple[dict, dict]:
    entry = variants.build_variant(spec, root)
    raw = evaluate.run_variant(entry, root, control=True)
    row = evaluate.score(raw, entry, truth.load_truth("headsq", root))
    return raw, row


def test_an_open_jaw_in_a_mirrored_turned_cm_file_is_found(corpus_root: Path) -> None:
    spec = _spec(950, mandible="opened", opening_deg=15.0, mirror_axis=0, units="cm", **_axes(1))
    raw, row = _scored(spec, corpus_root)
    assert raw["outcome"] == "confident", raw.get("self_check")
    # the same pose as the hint gives on this very mesh, and near the clean one
    assert row["max_error_vs_hinted_same_mesh_mm"] < 5.0
    assert row["max_error_mm"] < 10.0
    # the landmarks as a user receives them (g snapped to the brow's most forward point) are
    # scored against the truth's, snapped alike, in the file's own (mirrored, cm) frame
    assert set(raw["landmarks_snapped"]) == set(truth.SIX)
    assert row["max_error_snapped_mm"] < 10.0
    assert row["mandible_found"]
    assert abs(row["opening_error_deg"]) < 4.0


def test_a_table_and_a_head_holder_are_left_out(corpus_root: Path) -> None:
    for index, apparatus in ((951, "table"), (952, "holder")):
        spec = _spec(index, apparatus=apparatus, mandible="detached", **_axes(index))
        raw, row = _scored(spec, corpus_root)
        assert raw["outcome"] != "refused", raw.get("message")
        assert any("not bone was left out" in w for w in raw["warnings"]), raw["warnings"]
        assert row["max_error_vs_hinted_same_mesh_mm"] < 5.0
        assert row["max_error_mm"] < 10.0
        assert row["mandible_found"]


def test_a_missing_jaw_with_pins_is_not_invented(corpus_root: Path) -> None:
    spec = _spec(953, mandible="missing", apparatus="pins", **_axes(7))
    raw, row = _scored(spec, corpus_root)
    assert raw["outcome"] != "refused", raw.get("message")
    assert not row["has_mandible"] and not row["mandible_found"]
    assert row["max_error_vs_hinted_same_mesh_mm"] < 5.0
    assert row["max_error_mm"] < 10.0
