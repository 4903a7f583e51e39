"""Validation of a session folder (spec chapter 4).

:func:`validate_session` checks a session folder against chapters 1–3 and reports **every** problem
it finds as a coded :class:`~haptify.errors.Finding` (codes from ``schemas/<v>/codes.json``), grouped by
trial and file. It never raises for bad input and never reads anything outside the session folder:
paths are resolved lexically, symbolic link by symbolic link, and a path that would leave the folder is
reported (E108/E109) before anything is opened (spec §4.2).

The checks run in the order of spec §4.3, one module per family:

- :mod:`~haptify.formats.validation.manifest` — session.json: well-formedness, JSON Schema
  (:mod:`~haptify.formats.validation.schema`), the device file and its kinematic chain
  (:mod:`~haptify.formats.validation.device`), ids, cross references (§4.3.1–4.3.2);
- :mod:`~haptify.formats.validation.trials` — protocol requirements, rendering, label, powered flag (§4.3.3);
- :mod:`~haptify.formats.validation.streams` — every stream: path safety and size limits
  (:mod:`~haptify.formats.validation.files`), checksum, readability, columns and units, frame, rows; its time
  column (:mod:`~haptify.formats.validation.times`: time, rate) and its values (:mod:`~haptify.formats.validation.values`:
  NaN policy, infinities, quaternion norms, sensor ranges); last the time overlap of each trial's streams
  (§4.3.5–4.3.6, §4.4);
- :mod:`~haptify.formats.validation.report` — the report and its exit code (§4.6);
  :mod:`~haptify.formats.validation.validator` — the two phases together.
"""

from __future__ import annotations

from haptify.formats.validation.base import StreamEntry
from haptify.formats.validation.device import kinematics_findings
from haptify.formats.validation.files import stream_size_limit
from haptify.formats.validation.report import FindingModel, ReportItem, ValidationReport, ValidationReportModel
from haptify.formats.validation.schema import schema_findings
from haptify.formats.validation.times import RATE_TOLERANCE
from haptify.formats.validation.trials import NORMAL_NORM_TOLERANCE
from haptify.formats.validation.validator import SessionValidator, validate_session
from haptify.formats.validation.values import MOCAP_KINDS, OCCLUSION_WARNING_SHARE

__all__ = [
    "MOCAP_KINDS",
    "NORMAL_NORM_TOLERANCE",
    "OCCLUSION_WARNING_SHARE",
    "RATE_TOLERANCE",
    "FindingModel",
    "ReportItem",
    "SessionValidator",
    "StreamEntry",
    "ValidationReport",
    "ValidationReportModel",
    "kinematics_findings",
    "schema_findings",
    "stream_size_limit",
    "validate_session",
]
