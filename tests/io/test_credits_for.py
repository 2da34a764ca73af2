"""Credit lines of inputs (the NLM Visible Human credit) for the reports that use them."""

from __future__ import annotations

from pathlib import Path

from workbench.core.headgen.skin import build_skin
from workbench.io.mesh_formats import ply
from workbench.io.meshes import write_mesh
from workbench.io.samples import credit_comment, credits_for, registry


def test_credits_from_mesh_headers_and_registered_hashes(tmp_path: Path) -> None:
    mesh = build_skin("female").mesh
    plain = write_mesh(tmp_path / "plain.ply", mesh)
    credited = ply.write(tmp_path / "c.ply", mesh, comments=[credit_comment("Credit A.")])
    assert credits_for([plain, None]) == []
    assert credits_for([credited, credited, plain]) == ["Credit A."]  # once each
    vhp = next(s for s in registry().values() if s.credit)
    assert credits_for([], [vhp.files[0].sha256, "0" * 64]) == [vhp.credit]
    assert credits_for([tmp_path / "missing.ply"]) == []
