"""Age. Growth and age: facial norms by age and sex and the head warped to a new landmark
configuration (``change``), and the age job with its outputs and report data (``job``).

May import: core, model, io, ``landmarks``, ``templates``, ``animation`` (glTF of the aged
head).
"""
