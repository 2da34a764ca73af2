"""Landmarks. Landmarks on skulls and skins: the Frankfort head frame from landmarks
(``frame``), snapping to the feature a definition names (``snap``), transfer from the
reference head by a coarse alignment (``transfer``, ``alignment``) and the placement order
and checks of the window's tool (``placement``).

May import: core, model, io, ``templates``.
"""
