"""Implementations for the challenge tests (spec §17.8), in the ``--python module:function`` form."""

from __future__ import annotations

from haptify.conform_adapter import analyse


def off_by_one_percent(session: str, metric: str = "", parameters: dict | None = None) -> dict:
    """The reference with vibration.rms 1 % high, under its own name: a wrong implementation."""
    doc = analyse(session, metric, parameters)
    doc["implementation"] = {"name": "off-by-one-percent", "version": "0.1"}
    for m in doc.get("metrics", []):
        if m["id"] == "vibration.rms":
            m["value"] *= 1.01
    return doc


def stiffness_ten_percent(session: str, metric: str = "", parameters: dict | None = None) -> dict:
    """The reference with the stiffness 10 % high (and so its accuracy), under its own name: an implementation
    wrong in one family other than vibration."""
    doc = analyse(session, metric, parameters)
    doc["implementation"] = {"name": "stiffness-ten-percent", "version": "0.1"}
    for m in doc.get("metrics", []):
        if m["id"] in ("stiffness.measured", "stiffness.accuracy"):
            m["value"] *= 1.1
    return doc
