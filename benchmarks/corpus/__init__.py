"""Robustness corpus for the automatic skull registration (issue 28).

Bone meshes made the way other programs make them, from every real CT the
project has (the VTK ``headsq`` quarter CT and the Visible Human Female and
Male head CTs), in random file axes and units, with open or shifted jaws,
missing or detached mandibles, extra anatomy, apparatus and cuts.  Each
variant carries its ground truth: the base CT's clean *hinted* registration
carried through the same transforms.  The corpus measures the registration;
it never calls it on a variant except in :mod:`benchmarks.corpus.evaluate`.

Modules
-------
``common``    paths, hashing, JSON helpers, rigid-transform helpers
``bases``     the base CTs, their voxel label volumes (cranium / mandible /
              C-spine and hyoid / other) and check images
``truth``     the clean hinted registration of each base: landmarks, condylar
              axis, jaw opening (one definition, :func:`truth.jaw_opening`)
``variants``  the seeded spec generator and the mesh builder
``evaluate``  the automatic registration of each variant, scored

Units and frames
----------------
Everything is in millimetres.  The **input frame** of a base is the CT's
physical frame as :func:`workbench.services.ct.ct_mesh.mesh_from_ct` returns it
(LPS for the NRRD ``headsq``, RAS for the NIfTI VHP volumes).  The **head
frame** is the project's (x to the subject's left, y up, z toward the face,
Frankfort Horizontal at y = 0).  A variant's **file frame** is the base input
frame mapped by the variant's rigid transform (a reflection when mirrored);
a "cm" file holds those coordinates times 0.1 and is read back with
``units="cm"``, which returns the file frame in mm.

Running
-------
``benchmarks/bench_robustness.py --label NAME`` builds what is missing and
scores every variant (``--quick``: 12 of them; ``--only BASE``, ``--ids``,
``--limit N``, ``--sample N``, ``--jobs N``; ``--code HEAD`` measures a
committed revision while the working tree is being edited).  The tests in
``tests/benchmarks_cases/test_robustness_corpus.py`` check the instrument.

Generated meshes, volumes and results go under ``benchmarks/results/corpus/``
(git-ignored): meshes derived from the CTs are never committed.  Visible
Human data: Courtesy of the U.S. National Library of Medicine.
"""
