"""Animation. Animation: the mass-spring skin driven by muscles, jaw, gaze and lids
(``animator``), keyframe tracks and their editing (``track``, ``track_edit``), speech from
text (``speech``) and glTF export of expressions and clips (``gltf``).

May import: core, model, io, ``landmarks``, ``templates``.
"""
