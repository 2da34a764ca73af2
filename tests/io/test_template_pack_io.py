"""Template packs: export, read back, refuse edited packs (io.template_pack, services.template_cache)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from workbench.core.errors import InputError
from workbench.io.template_pack import export_template, load_template_pack
from workbench.services.templates.cache import reference_head, source_key


def test_pack_round_trip_keeps_every_part_and_the_hash(head_female, tmp_path):
    export_template(head_female, tmp_path / "pack")
    again = load_template_pack(tmp_path / "pack")
    assert again.content_hash == head_female.content_hash
    assert again.template_id == head_female.template_id
    for part, mesh in head_female.meshes.items():
        assert again.meshes[part].equals(mesh), part
    assert [m.code for m in again.muscles] == [m.code for m in head_female.muscles]
    np.testing.assert_array_equal(again.tmj_axis, head_female.tmj_axis)
    assert again.skull_landmark_part == head_female.skull_landmark_part


def test_edited_or_incomplete_pack_is_refused(head_female, tmp_path):
    pack = tmp_path / "pack"
    export_template(head_female, pack)
    info = json.loads((pack / "template.json").read_text())
    info["eye_radius_mm"] = 99.0  # not hashed, but the skin is:
    (pack / "template.json").write_text(json.dumps(info))
    doc = json.loads((pack / "skin.mrk.json").read_text())
    doc["markups"][0]["controlPoints"][0]["position"][0] += 1.0
    (pack / "skin.mrk.json").write_text(json.dumps(doc))
    with pytest.raises(InputError, match="hash"):
        load_template_pack(pack)
    (pack / "mandible.ply").unlink()
    with pytest.raises(InputError, match="mandible.ply"):
        load_template_pack(pack)
    with pytest.raises(InputError, match="template.json"):
        load_template_pack(tmp_path)


def test_every_source_of_the_cache_key_exists() -> None:
    # a pattern that matches nothing leaves edits to those files out of the key, and a
    # stale cached head in use (after the move to services/templates/ the package root
    # was services/, and no source file counted)
    from workbench.services.templates import cache

    roots = [(cache._PACKAGE, cache._SOURCE_GLOBS), (cache._tables_root(), cache._TABLE_GLOBS)]
    for root, patterns in roots:
        for pattern in patterns:
            assert any(root.glob(pattern)), f"{pattern} matches nothing under {root}"
    assert (cache._PACKAGE / "core" / "headgen" / "skin.py").is_file()


def test_cached_head_is_reused_and_keyed_by_sources(head_male):
    key = source_key()
    assert len(key) == 16
    again = reference_head("male")  # from the session cache: same content
    assert again.content_hash == head_male.content_hash
    with pytest.raises(InputError, match="sex"):
        reference_head("other")
