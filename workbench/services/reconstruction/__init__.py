"""Reconstruction. Skull to face: the fit of the reference head over a registered skull
(``reconstruct``), the one pipeline the command line, the window and batch call
(``service``, with the checks of its settings and face in ``fit_checks``), the three build
faces and the 95 % band (``build_faces``), the job that opens a case, fits and writes the
outputs and report data (``job``) and the window's quick preview while a dowel is dragged
(``preview_fit``).

May import: core, model, commands, io and the packages below it: case, landmarks, templates,
registration, tissue, guides.
"""
