"""The Case document and its parts: plain data, no Qt, no VTK."""

from __future__ import annotations

from workbench.model.audit import AuditLog
from workbench.model.case import PARTS, Case, EvidenceConflictError
from workbench.model.evidence import EvidenceFile
from workbench.model.meta import CaseMeta
from workbench.model.reconstruction_setup import DowelSettings, GuideList, Orientation
from workbench.model.specimen import Specimen

__all__ = [
    "PARTS",
    "AuditLog",
    "Case",
    "CaseMeta",
    "DowelSettings",
    "EvidenceConflictError",
    "EvidenceFile",
    "GuideList",
    "Orientation",
    "Specimen",
]
