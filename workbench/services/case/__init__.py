"""Cases. Opening a case: a skull file read, checked and turned into a case with its evidence
(``case_setup``), and the cheap checks that refuse a bad skull mesh or landmarks before any
work (``input_checks``).

May import: core, model, commands, io.
"""
