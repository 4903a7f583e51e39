"""The submission bundle's manifest ``bundle.json`` and the bundle's identity (spec §17.2).

The models here are the source of the normative schema ``schemas/<v>/bundle.schema.json``; packing,
unpacking and checking a bundle belong to the registry tools, which import them.
"""

from __future__ import annotations

import hashlib
import json
from typing import Final, Literal

from pydantic import BaseModel, ConfigDict, Field

from haptify.formats.session_format import Id, Rig
from haptify.pipeline.results import Implementation
from haptify.versions import SPEC_VERSION

BUNDLE_FORMAT: Final = "haptify-bundle/1"
BUNDLE_JSON = "bundle.json"
RESULTS_JSON = "results.json"
CONFORMANCE_JSON = "conformance.json"
SESSION_DIR = "session"

Role = Literal["results", "conformance", "session-manifest", "session-file", "stream"]


class BundleFile(BaseModel):
    """One file of the bundle: path, role, size in bytes and sha256 (spec §17.2.1, §17.2.2)."""

    model_config = ConfigDict(extra="forbid")
    path: str = Field(description="Relative POSIX path inside the archive.")
    role: Role
    size: int = Field(ge=0, description="Bytes.")
    sha256: str = Field(pattern=r"^[0-9a-f]{64}$")


class BundleLab(BaseModel):
    """The lab a bundle comes from: the session's lab.id, which must be the submitting token's lab (spec §17.2.2, §17.6)."""

    model_config = ConfigDict(extra="forbid")
    id: Id = Field(description="The session's lab.id; must be the lab of the submitting token.")


class BundleDevice(BaseModel):
    """The device a bundle's results describe, as in the session's device description (spec §17.2.2, §2.3)."""

    model_config = ConfigDict(extra="forbid")
    manufacturer: str = Field(min_length=1, max_length=200)
    model: str = Field(min_length=1, max_length=200)
    serial: str | None = Field(default=None, max_length=200)


class Bundle(BaseModel):
    """``bundle.json`` (spec §17.2); its JSON Schema is generated from this model."""

    model_config = ConfigDict(extra="forbid")
    format: Literal["haptify-bundle/1"] = BUNDLE_FORMAT
    spec_version: str = SPEC_VERSION
    lab: BundleLab
    device: BundleDevice
    rig: Rig = Field(description="The rig description, copied from the session manifest.")
    implementation: Implementation = Field(description="Name and version of the software that computed results.json.")
    session_id: str
    includes_raw: bool = Field(description="True when the session's stream files are included (then the registry re-computes).")
    supersedes: str | None = Field(
        default=None, pattern=r"^[0-9a-f]{20}$", description="Id of the lab's earlier submission this one corrects."
    )
    files: list[BundleFile] = Field(min_length=2)

    def file(self, role: Role) -> BundleFile | None:
        return next((f for f in self.files if f.role == role), None)


def canonical_json(payload: object) -> bytes:
    """Canonical JSON bytes: sorted keys, no insignificant whitespace, UTF-8 (spec §17.2)."""
    return json.dumps(payload, sort_keys=True, separators=(",", ":"), ensure_ascii=False).encode("utf-8")


def bundle_digest(bundle: Bundle) -> str:
    """The bundle's identity: sha256 (hex) of the canonical JSON of ``bundle.json`` (spec §17.2)."""
    return hashlib.sha256(canonical_json(bundle.model_dump(mode="json"))).hexdigest()


def submission_id(digest: str) -> str:
    """The registry id of a bundle: the first 20 hex digits of its digest (same digest → same id).
    Spec §17.1, §17.2.3."""
    return digest[:20]
