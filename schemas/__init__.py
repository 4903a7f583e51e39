"""Haptify's normative JSON data (schemas, metric definitions, code catalogue) as package data (spec §0.3).

The standard's data is the source: the spec and schema versions are stated here, beside the data they
version, and every reader — the reference (:mod:`haptify.schemas`) and the conformance judge alike — reads
the files through :func:`load`, never by path from a checkout. Files are parsed once and cached; callers
must not mutate what they get.
"""

from __future__ import annotations

import json
from functools import lru_cache
from importlib import resources
from typing import Any

#: The version of the spec these files belong to; also the name of their folder (spec §2.8).
SPEC_VERSION = "1.0"
#: The version written into every schema's ``$id`` (spec §2.8).
SCHEMA_VERSION = "1.0.0"


def _root():
    return resources.files(__name__) / SPEC_VERSION


@lru_cache(maxsize=None)
def load(name: str) -> Any:
    """Parse ``schemas/<spec version>/<name>`` (e.g. ``"codes.json"``, ``"metrics/vibration.rms.json"``)."""
    return json.loads((_root() / name).read_text(encoding="utf-8"))


def list_dir(sub: str) -> list[str]:
    """Names of the JSON files in ``schemas/<spec version>/<sub>``, sorted."""
    folder = _root() / sub
    return sorted(p.name for p in folder.iterdir() if p.name.endswith(".json"))


def schema(name: str) -> dict:
    """The JSON Schema called ``name`` (``"session"`` → ``session.schema.json``; spec §0.3)."""
    return load(f"{name}.schema.json")
