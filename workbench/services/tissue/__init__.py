"""Tissue depths. Soft tissue over the skull: tissue-depth dowels from cited tables, with the
build model's regional depths for slender, average, heavy or a BMI (``dowels``,
``dowel_sites``), and the tissue model calibrating the reference's own thickness
(``tissue_model``).

May import: core, model, io, ``templates`` (the reference's bone).
"""
