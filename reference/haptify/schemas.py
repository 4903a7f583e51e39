"""Access to the normative JSON data shipped in ``schemas/`` (spec §0.3).

Everything is read from the installed package data, so it works from a wheel as well as from a
checkout. Files are parsed once and cached; callers must not mutate what they get.
"""

from __future__ import annotations

import json
from functools import lru_cache
from importlib import resources
from typing import Any

from haptify.versions import SPEC_VERSION


def _root():
    return resources.files("haptify_schemas") / SPEC_VERSION


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
