"""Strict JSON documents (spec §3.1, §4.3, §4.6): parsing without NaN, overflowing numbers or repeated member
names, pydantic errors as findings with JSON pointers, and reading a standalone document into a model.
"""

from __future__ import annotations

import json
import math
import os
from pathlib import Path
from typing import Any, Iterable, TypeVar

from pydantic import BaseModel, ValidationError

from haptify.codes import Code
from haptify.errors import Finding, HaptifyError, fail


def pointer_of(loc: Iterable[Any]) -> str:
    """A JSON pointer (RFC 6901) from a pydantic/jsonschema location tuple (spec §4.6)."""
    parts = [str(p).replace("~", "~0").replace("/", "~1") for p in loc]
    return "/" + "/".join(parts) if parts else ""


class _NonFinite(ValueError):
    pass


class _DuplicateKey(ValueError):
    def __init__(self, key: str) -> None:
        super().__init__(key)
        self.key = key


def _unique_members(pairs: list[tuple[str, Any]]) -> dict[str, Any]:
    """A JSON object's members; a name given twice is an error (spec §3.1), not a silent overwrite."""
    out: dict[str, Any] = {}
    for key, value in pairs:
        if key in out:
            raise _DuplicateKey(key)
        out[key] = value
    return out


def _reject_constant(name: str) -> float:
    raise _NonFinite(f"{name} is not a JSON number")


def _finite_float(text: str) -> float:
    value = float(text)
    if not math.isfinite(value):
        raise _NonFinite(f"the number {text} overflows a 64-bit float")
    return value


def parse_json_file(path: Path, code: Code, label: str) -> Any:
    """Parse a JSON file strictly: UTF-8, no NaN/Infinity literals, no numbers that overflow, no member
    name twice in one object (E117) (spec §3.1, §4.3)."""
    try:
        text = path.read_bytes().decode("utf-8")
    except UnicodeDecodeError as exc:
        raise HaptifyError(
            Finding(
                code,
                f"{label} is not UTF-8 text: {exc.reason} at byte {exc.start}",
                file=label,
                expected="UTF-8 JSON",
                found=f"byte 0x{exc.object[exc.start]:02x}",
            )
        ) from None
    except OSError as exc:
        raise HaptifyError(Finding(code, f"{label} cannot be read: {exc.strerror}", file=label)) from None
    try:
        return json.loads(text, parse_constant=_reject_constant, parse_float=_finite_float, object_pairs_hook=_unique_members)
    except json.JSONDecodeError as exc:
        raise HaptifyError(
            Finding(
                code,
                f"{label} is not well-formed JSON: {exc.msg} (line {exc.lineno}, column {exc.colno})",
                file=label,
                expected="JSON",
                found=text[max(0, exc.pos - 20) : exc.pos + 20],
            )
        ) from None
    except _DuplicateKey as exc:
        raise HaptifyError(
            Finding(
                Code.JSON_DUPLICATE_KEY,
                f"{label} names the member {short_text(exc.key)!r} twice in one object",
                file=label,
                expected="unique member names",
                found=short_text(exc.key),
            )
        ) from None
    except _NonFinite as exc:
        raise HaptifyError(
            Finding(code, f"{label} is not well-formed JSON: {exc}", file=label, expected="a finite JSON number")
        ) from None
    except RecursionError:
        raise HaptifyError(Finding(code, f"{label} nests too deeply to be a Haptify document", file=label)) from None


def pydantic_findings(exc: ValidationError, code: Code, label: str) -> list[Finding]:
    """One finding per pydantic error, with JSON pointer and expected/found (spec §4.6)."""
    out = []
    for err in exc.errors(include_url=False):
        found = err.get("input")
        if isinstance(found, (dict, list)):
            found = f"<{type(found).__name__}>"
        out.append(
            Finding(
                code,
                f"{err['msg']}",
                file=label,
                pointer=pointer_of(err["loc"]),
                expected=err.get("ctx", {}).get("expected", err["type"]),
                found=found,
            )
        )
    return out


M = TypeVar("M", bound=BaseModel)


def read_json_model(path: str | os.PathLike[str], model: type[M], code: Code) -> M:
    """Read a JSON file into a pydantic ``model``; a missing, malformed or invalid file is ``code``.
    Spec §0.4.

    Used for every standalone document (results files, model parameter files): the finding names the
    file, the JSON pointer of each invalid field, what was expected and what was found.
    """
    p = Path(path)
    if not p.is_file():
        raise fail(code, f"{str(p)!r} does not exist or is not a file", file=str(p))
    data = parse_json_file(p, code, str(p))
    try:
        return model.model_validate(data)
    except ValidationError as exc:
        raise HaptifyError(*pydantic_findings(exc, code, str(p))) from None


def short_text(text: str) -> str:
    """``text`` cut to 80 characters for a finding's ``found``."""
    return text if len(text) <= 80 else text[:77] + "..."
