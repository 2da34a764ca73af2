"""Temporary: the PDF hook of the age export under its old import path.

``workbench gui`` imports :func:`set_pdf_hook` from here; the hook now lives in
:mod:`workbench.qt.tools.age.work`.  This module goes once the command line
imports it from there.
"""

from workbench.qt.tools.age.work import pdf_hook, set_pdf_hook

__all__ = ["pdf_hook", "set_pdf_hook"]
