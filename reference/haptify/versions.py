"""Every version string (spec §2.8).

The package version is defined here and nowhere else (pyproject.toml reads PACKAGE_VERSION); the spec
version and the schema version belong to the normative data and are stated beside it, in ``haptify_schemas``
(the schema generator writes SCHEMA_VERSION into every ``$id`` under ``schemas/``).
"""

from haptify_schemas import SCHEMA_VERSION as SCHEMA_VERSION, SPEC_VERSION as SPEC_VERSION

PACKAGE_VERSION = "0.1.0"
SCHEMA_BASE_URI = "https://haptify.org/schemas"


def schema_id(name: str) -> str:
    """The ``$id`` of schema ``name`` (e.g. ``"session"``) for the current spec version."""
    return f"{SCHEMA_BASE_URI}/{SPEC_VERSION}/{name}.schema.json"
