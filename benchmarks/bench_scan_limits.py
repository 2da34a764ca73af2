"""Benchmark: ``workbench fit-scan`` on scans that used to exhaust memory or time (issue 29).

Run ``python benchmarks/bench_scan_limits.py [CASE ...]`` from the repository
root with WORKBENCH_SAMPLE_MIRRORS set (or ``../shared/data`` beside the
checkout).  Each case is written to a scratch folder and fitted by the CLI in
a child process, which reports its own wall time and peak resident memory
(``ru_maxrss``).  The target: a 5 M-triangle scan fits or is refused in under
60 s and 4 GB.

Cases (mm):

* ``vhf_5m``: the Visible Human female head CT's skin surface (1 mm volume,
  ~590k triangles; courtesy of the U.S. National Library of Medicine), each
  triangle split into 9 (its edges in thirds): ~5.3 M triangles, binary PLY;
* ``vhf_5m_soup``: the same written as a triangle soup (every triangle its
  own three vertices, ~16 M vertices); both with ``--units mm`` and the
  sample registry's orientation of the volume;
* ``headsq_soup``: the headsq CT's skin as a triangle soup (the issue's
  23 GB case);
* ``headsq_12_textures``: the headsq skin as OBJ with 12 materials, each an
  8192 x 8192 texture image (the issue's MemoryError case).
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
os.environ.setdefault("WORKBENCH_SAMPLE_MIRRORS", str(ROOT.parent / "shared" / "data"))

CHILD = """
import resource, sys, time
from workbench.cli.main import main
t = time.perf_counter()
try:
    code = main(sys.argv[1:])
except SystemExit as exc:
    code = exc.code
print("BENCH", code, round(time.perf_counter() - t, 2),
      resource.getrusage(resource.RUSAGE_SELF).ru_maxrss, flush=True)
"""


def _trisect(v: np.ndarray, f: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Each triangle split into 9 (edge thirds and a centre point), welded: shared edges
    get their two new points once."""
    m, n = len(f), len(v)
    e = np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]])
    key = np.sort(e, axis=1)
    uniq, inv = np.unique(key[:, 0] * n + key[:, 1], return_inverse=True)
    a, b = uniq // n, uniq % n
    k = len(uniq)
    third = np.vstack([v[a] + (v[b] - v[a]) / 3, v[a] + 2 * (v[b] - v[a]) / 3, v[f].mean(axis=1)])
    verts = np.vstack([v, third])
    inv = inv.reshape(3, m).T  # (m, 3): edge of corner pair h

    def point(h: int, t: int) -> np.ndarray:
        """The point 1/3 (t=1) or 2/3 (t=2) along corner pair h from its first corner."""
        u = inv[:, h]
        forward = e[h * m : (h + 1) * m, 0] == a[u]
        near, far = n + u, n + k + u
        return np.where(forward == (t == 1), near, far)

    c = n + 2 * k + np.arange(m)
    p0, p1, p2 = f[:, 0], f[:, 1], f[:, 2]
    a1, a2 = point(0, 1), point(0, 2)  # on 0-1
    b1, b2 = point(1, 1), point(1, 2)  # on 1-2
    c1, c2 = point(2, 1), point(2, 2)  # on 2-0
    faces = np.concatenate(
        [
            np.c_[p0, a1, c2],
            np.c_[a1, c, c2],
            np.c_[a1, a2, c],
            np.c_[a2, b1, c],
            np.c_[a2, p1, b1],
            np.c_[b1, b2, c],
            np.c_[b2, c1, c],
            np.c_[b2, p2, c1],
            np.c_[c1, c2, c],
        ]
    )
    return verts, faces


def _soup(v: np.ndarray, f: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    return v[f].reshape(-1, 3), np.arange(3 * len(f)).reshape(-1, 3)


def _write_ply(path: Path, v: np.ndarray, f: np.ndarray) -> None:
    """A binary PLY written directly (float32 vertices, uint8 count + int32 indices)."""
    head = (
        f"ply\nformat binary_little_endian 1.0\nelement vertex {len(v)}\n"
        "property float x\nproperty float y\nproperty float z\n"
        f"element face {len(f)}\nproperty list uchar int vertex_indices\nend_header\n"
    ).encode()
    rows = np.zeros(len(f), dtype=[("n", "u1"), ("i", "<i4", (3,))])
    rows["n"], rows["i"] = 3, f
    with open(path, "wb") as out:
        out.write(head)
        out.write(np.ascontiguousarray(v, "<f4").tobytes())
        out.write(rows.tobytes())


def _vhf_skin() -> tuple[np.ndarray, np.ndarray]:
    from workbench.io.samples import fetch
    from workbench.services.ct.ct_mesh import mesh_from_ct

    m = mesh_from_ct(fetch("vhp_female"), "skin").mesh
    return m.vertices, m.faces


def _headsq_skin() -> tuple[np.ndarray, np.ndarray]:
    from workbench.io.samples import fetch
    from workbench.services.ct.ct_mesh import mesh_from_ct

    m = mesh_from_ct(fetch("headsq"), "skin").mesh
    return m.vertices, m.faces


def _textured_obj(folder: Path, v: np.ndarray, f: np.ndarray, images: int, side: int) -> Path:
    from PIL import Image

    x = np.linspace(0, 255, side, dtype=np.float32)
    gradient = np.stack(np.broadcast_arrays(x[None, :], x[:, None], 128.0 + 0 * x[None, :]), -1)
    Image.fromarray(gradient.astype(np.uint8)).save(folder / "t0.png", compress_level=1)
    data = (folder / "t0.png").read_bytes()
    for k in range(1, images):
        (folder / f"t{k}.png").write_bytes(data)
    uv = (v[:, :2] - v[:, :2].min(0)) / np.ptp(v[:, :2], axis=0)
    lines = ["mtllib scan.mtl", *(f"v {a:.5f} {b:.5f} {c:.5f}" for a, b, c in v)]
    lines += [f"vt {a:.5f} {b:.5f}" for a, b in uv]
    for k, chunk in enumerate(np.array_split(f + 1, images)):
        lines.append(f"usemtl m{k}")
        lines += [f"f {a}/{a} {b}/{b} {c}/{c}" for a, b, c in chunk]
    (folder / "scan.obj").write_text("\n".join(lines) + "\n")
    (folder / "scan.mtl").write_text(
        "".join(f"newmtl m{k}\nmap_Kd t{k}.png\n" for k in range(images))
    )
    return folder / "scan.obj"


def _vhf_options() -> list[str]:
    """mm (the CT's skin with its neck is ~370 mm: "units unclear" without them) and the
    sample registry's anatomy of the volume."""
    from workbench.io.samples import registry

    a = registry()["vhp_female"].anatomy
    axes = [("--anterior", "anterior"), ("--superior", "superior"), ("--left", "left")]
    out = ["--units", "mm"]
    for option, key in axes:
        if key in a:
            out.append(f"{option}=" + ",".join(f"{x:g}" for x in a[key]))
    return out


def _cases(folder: Path):
    def vhf_5m() -> list[str]:
        v, f = _trisect(*_vhf_skin())
        _write_ply(folder / "vhf_5m.ply", v, f)
        return [str(folder / "vhf_5m.ply"), *_vhf_options()]

    def vhf_5m_soup() -> list[str]:
        v, f = _soup(*_trisect(*_vhf_skin()))
        _write_ply(folder / "vhf_5m_soup.ply", v, f)
        return [str(folder / "vhf_5m_soup.ply"), *_vhf_options()]

    def headsq_soup() -> list[str]:
        v, f = _soup(*_headsq_skin())
        _write_ply(folder / "headsq_soup.ply", v, f)
        return [str(folder / "headsq_soup.ply")]

    def headsq_12_textures() -> list[str]:
        sub = folder / "textured"
        sub.mkdir(exist_ok=True)
        return [str(_textured_obj(sub, *_headsq_skin(), images=12, side=8192))]

    return {
        "vhf_5m": vhf_5m,
        "vhf_5m_soup": vhf_5m_soup,
        "headsq_soup": headsq_soup,
        "headsq_12_textures": headsq_12_textures,
    }


def main(argv: list[str]) -> int:
    results = {}
    with tempfile.TemporaryDirectory(prefix="bench_scan_limits_") as tmp:
        folder = Path(tmp)
        cases = _cases(folder)
        for name in argv or list(cases):
            t = time.perf_counter()
            args = cases[name]()
            made = time.perf_counter() - t
            n_tri = _triangles(Path(args[0]))
            out = folder / f"pack_{name}"
            run = subprocess.run(
                [sys.executable, "-c", CHILD, "fit-scan", *args, "--out", str(out)],
                capture_output=True,
                text=True,
                cwd=ROOT,
            )
            line = next((x for x in run.stdout.splitlines() if x.startswith("BENCH")), "")
            parts = line.split()
            code, seconds, rss_kb = (
                (int(parts[1]), float(parts[2]), int(parts[3]))
                if parts
                else (run.returncode, float("nan"), 0)
            )
            said = [
                x for x in (run.stdout + run.stderr).splitlines() if "error" in x or "note" in x
            ]
            report = out / "fit_report.json"
            fig = json.loads(report.read_text()) if report.exists() else {}
            results[name] = {
                "file_triangles": n_tri,
                "exit": code,
                "seconds": seconds,
                "peak_rss_mb": round(rss_kb / 1024),
                "made_in_s": round(made, 1),
                "face_within_1mm_fraction": fig.get("face_within_1mm_fraction"),
                "fit_seconds": fig.get("seconds"),
                "scan_preparation": fig.get("scan_preparation"),
                "messages": said[:6],
            }
            r = results[name]
            print(
                f"{name:20s} {n_tri:>10,} triangles  exit {code}  {seconds:6.1f} s  "
                f"peak RSS {r['peak_rss_mb']:,} MB  within 1 mm {r['face_within_1mm_fraction']}",
                flush=True,
            )
    print(json.dumps(results, indent=2))
    return 0


def _triangles(path: Path) -> int:
    if path.suffix == ".ply":
        head = path.read_bytes()[:400].decode(errors="replace")
        return int(head.split("element face ")[1].split()[0])
    return sum(1 for line in path.open() if line.startswith("f "))


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
