"""CT. CT and MR volumes to surfaces: bone and skin iso-surfaces with HU presets (``ct_mesh``)
and the interactive preview of a level (``ct_preview``).

May import: core, model, io.
"""
