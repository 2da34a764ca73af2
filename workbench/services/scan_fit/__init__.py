"""Scan fitting. The reference head adapted to a range scan with holes: orientation,
dense skin registration, skull and inner parts placed at the table's depths, colour and
detail carried over.

Modules (each imports only those listed before it):

* ``settings``: the tunable constants and the result types (``ScanFit``, ``PreparedScan``);
* ``checks``: checks of the scan inputs and the scan made ready to fit (``prepare_scan``);
* ``sheets``: thin sheets of a scan that are not the face's skin (cords, bands, hair);
* ``placement``: step 1, the reference face laid on the scan (partial faces);
* ``skin``: step 2, the reference skin registered onto the scan;
* ``inside``: step 3, skull, teeth, tongue and eyes at the table's tissue depths;
* ``figures``: the fit's report figures and self-check;
* ``fit``: ``fit_scan``, the fit's steps in order;
* ``pack``: ``fit_scan_pack``, the files read and the template pack written.

May import: core, model, io, ``landmarks``, ``templates``, ``registration``, ``tissue``.
"""
