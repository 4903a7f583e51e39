"""JSON Schema validation of session.json and device.json (spec §4.3.1): every schema error as a coded
finding, the errors of an ``anyOf``/``oneOf`` taken from the branch the instance was meant to match.

An instance is first checked by jsonschema-rs (compiled, about a millisecond for a dossier's session.json);
only an instance it rejects goes through ``jsonschema``, whose errors carry what the findings report (the
branch an ``anyOf`` meant, the failing keyword's value). Both apply Draft 2020-12 with ``format`` as an
annotation, so they agree on what is valid (tests/test_schema_validators.py).
"""

from __future__ import annotations

import json
from functools import lru_cache
from typing import TYPE_CHECKING, Any

import jsonschema_rs
from pydantic import BaseModel

from haptify import schemas
from haptify.codes import Code
from haptify.errors import Finding
from haptify.formats.session_format import Device, Session
from haptify.formats.storage import pointer_of
from haptify.formats.validation.report import jsonable, short


if TYPE_CHECKING:
    from jsonschema import Draft202012Validator
    from jsonschema.exceptions import ValidationError as SchemaError


@lru_cache(maxsize=None)
def schema_document(name: str) -> dict[str, Any]:
    """``<name>.schema.json``; from the pydantic model when not yet generated."""
    try:
        document: dict[str, Any] = schemas.schema(name)
        return document
    except FileNotFoundError:
        models: dict[str, type[BaseModel]] = {"session": Session, "device": Device}
        return models[name].model_json_schema()


@lru_cache(maxsize=None)
def fast_validator(name: str) -> jsonschema_rs.Draft202012Validator:
    """jsonschema-rs's Draft 2020-12 validator of ``<name>.schema.json`` (``format`` not asserted)."""
    return jsonschema_rs.Draft202012Validator(schema_document(name), validate_formats=False)


@lru_cache(maxsize=None)
def detailed_validator(name: str) -> Draft202012Validator:
    """``jsonschema``'s Draft 2020-12 validator of ``<name>.schema.json``, for the errors' details."""
    from jsonschema import Draft202012Validator

    return Draft202012Validator(schema_document(name))


def _branch_errors(err: SchemaError) -> list[SchemaError]:
    """The leaf errors of the branch of an ``anyOf``/``oneOf`` that the instance was meant to match.

    A ``discriminator`` (pydantic's tagged unions) names the branch; otherwise branches whose type
    does not fit the instance are dropped and the one with the fewest errors is taken.
    """
    if err.validator not in ("anyOf", "oneOf") or not err.context:
        return [err]
    by_branch: dict[str | int, list[SchemaError]] = {}
    for sub in err.context:
        by_branch.setdefault(sub.relative_schema_path[0], []).append(sub)
    options = err.validator_value
    assert isinstance(options, list)  # the value of an anyOf / oneOf is its list of branches (JSON Schema §10.2.1)
    disc = err.schema.get("discriminator") if isinstance(err.schema, dict) else None
    if disc and isinstance(err.instance, dict):
        tag = err.instance.get(disc.get("propertyName"))
        target = disc.get("mapping", {}).get(tag) if isinstance(tag, str) else None
        if target is None:
            return [err]
        chosen = [i for i, o in enumerate(options) if o.get("$ref") == target]
        if not chosen or chosen[0] not in by_branch:
            return [err]
        branch = by_branch[chosen[0]]
    else:
        fitting = {
            i: errs for i, errs in by_branch.items() if not any(e.validator == "type" and not e.relative_path for e in errs)
        }
        if not fitting:
            return [err]
        branch = min(fitting.values(), key=len)
    out: list[SchemaError] = []
    for sub in branch:
        out.extend(_branch_errors(sub))
    return out


_SIZE_FIELDS = {"rows", "rate_hz", "loop_rate_hz"}


def _code_for(err: SchemaError, default: str) -> str:
    """Map a schema error to its catalogue code: E301 unknown protocol, E113 absurd size, else ``default``."""
    path = list(err.absolute_path)
    if default != Code.SCHEMA_VIOLATION:
        return default
    if len(path) == 3 and path[0] == "trials" and path[2] == "protocol" and err.validator == "enum":
        return Code.PROTOCOL_UNKNOWN
    if path and path[-1] in _SIZE_FIELDS and err.validator in ("maximum", "exclusiveMaximum"):
        return Code.DECLARED_SIZE_ABSURD
    return default


def schema_findings(instance: Any, schema_name: str, code: str, label: str) -> list[Finding]:
    """Every JSON Schema error of ``instance`` against ``<schema_name>.schema.json`` as findings (spec §4.3.1)."""
    if fast_validator(schema_name).is_valid(instance):
        return []
    out: list[Finding] = []
    for top in detailed_validator(schema_name).iter_errors(instance):
        for err in _branch_errors(top):
            expected = err.validator_value if err.validator not in ("anyOf", "oneOf", "$ref", "additionalProperties") else None
            if isinstance(expected, (dict, list)) and len(json.dumps(expected, default=str)) > 200:
                expected = None
            message = err.message if len(err.message) <= 300 else err.message[:297] + "..."
            out.append(
                Finding(
                    _code_for(err, code),
                    f"{schema_name}.schema.json: {message}",
                    file=label,
                    pointer=pointer_of(err.absolute_path),
                    expected=jsonable(expected) if expected is not None else err.validator,
                    found=jsonable(short(err.instance)),
                )
            )
    out.sort(key=lambda f: f.pointer or "")
    return out
