"""Scan fitting. The reference head adapted to a range scan with holes (``fit``): orientation,
dense skin registration, skull and inner parts placed at the table's depths, colour and
detail carried over.

May import: core, model, io, ``landmarks``, ``templates``, ``registration``, ``tissue``.
"""
