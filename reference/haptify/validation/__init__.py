"""Validation of a session folder (spec chapter 4).

:func:`validate_session` checks a session folder against chapters 1–3 and reports **every** problem
it finds as a coded :class:`~haptify.errors.Finding` (codes from ``schemas/<v>/codes.json``), grouped by
trial and file. It never raises for bad input and never reads anything outside the session folder:
paths are resolved lexically, symbolic link by symbolic link, and a path that would leave the folder is
reported (E108/E109) before anything is opened (spec §4.2).

The checks run in the order of spec §4.3, one module per family:

- :mod:`~haptify.validation.manifest` — session.json: well-formedness, JSON Schema
  (:mod:`~haptify.validation.schema`), the device file and its kinematic chain
  (:mod:`~haptify.validation.device`), ids, cross references (§4.3.1–4.3.2);
- :mod:`~haptify.validation.trials` — protocol requirements, rendering, label, powered flag (§4.3.3);
- :mod:`~haptify.validation.streams` — every stream: path safety and size limits
  (:mod:`~haptify.validation.files`), checksum, readability, columns and units, frame, rows; its time
  column (:mod:`~haptify.validation.times`: time, rate) and its values (:mod:`~haptify.validation.values`:
  NaN policy, infinities, quaternion norms, sensor ranges); last the time overlap of each trial's streams
  (§4.3.5–4.3.6, §4.4);
- :mod:`~haptify.validation.report` — the report and its exit code (§4.6);
  :mod:`~haptify.validation.validator` — the two phases together.
"""

from __future__ import annotations

from haptify.validation.base import StreamEntry
from haptify.validation.device import kinematics_findings
from haptify.validation.files import stream_size_limit
from haptify.validation.report import FindingModel, ReportItem, ValidationReport, ValidationReportModel
from haptify.validation.schema import schema_findings
from haptify.validation.times import RATE_TOLERANCE
from haptify.validation.trials import NORMAL_NORM_TOLERANCE
from haptify.validation.validator import SessionValidator, validate_session
from haptify.validation.values import MOCAP_KINDS, OCCLUSION_WARNING_SHARE

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
