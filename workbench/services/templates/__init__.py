"""Reference heads. The reference head: the built-in heads and template packs (``template``,
``cache``), its parts as meshes (``reference_parts``), the six face regions of its skin
(``regions``), the muscles laid on its skin (``muscles``) and a head adapted to a person's
CT or scans (``build``).

May import: core, model, io, ``case``, ``registration``, ``landmarks``.
"""
