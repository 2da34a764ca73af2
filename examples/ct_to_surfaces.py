"""CT to bone and skin surfaces, and a soft-tissue thickness map, without the GUI.

Run with ``python examples/ct_to_surfaces.py [OUT_DIR]``.  Uses the public
``headsq`` CT (downloaded on first use) and only the scriptable services:

1. extract the bone and skin iso-surfaces (mm, in the volume's frame);
2. measure, for every skin vertex, the distance to the bone surface — the
   total soft-tissue thickness a tissue-depth table tabulates;
3. save both meshes and print the thickness over the face.
"""

# %%
from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

from workbench.core.spatial import MeshIndex
from workbench.io.meshes import write_mesh
from workbench.samples import fetch, registry
from workbench.services.ct.ct_mesh import mesh_from_ct

out = Path(sys.argv[1]) if len(sys.argv) > 1 else Path("example_out")
out.mkdir(parents=True, exist_ok=True)
ct = fetch("headsq")

# %% Surfaces
bone = mesh_from_ct(ct, tissue="bone").mesh
skin = mesh_from_ct(ct, tissue="skin").mesh
write_mesh(out / "bone.ply", bone)
write_mesh(out / "skin.ply", skin)
print(f"bone: {bone.n_faces} triangles, skin: {skin.n_faces} triangles")

# %% Soft-tissue thickness: distance from each skin vertex to the bone surface
thickness_mm = MeshIndex(bone).closest_points(skin.vertices).distances
anatomy = registry()["headsq"].anatomy
anterior = np.asarray(anatomy["anterior"], float)
# the face: skin vertices in the most anterior 40 mm of the head
depth = skin.vertices @ anterior
face = depth > depth.max() - 40.0
q = np.percentile(thickness_mm[face], [10, 50, 90])
print(
    f"facial soft tissue over {face.sum()} skin vertices: "
    f"10th {q[0]:.1f} mm, median {q[1]:.1f} mm, 90th {q[2]:.1f} mm"
)
