"""The one source of every version string (spec §2.8).

The package version, the spec version and the schema version are defined here and nowhere else:
pyproject.toml reads PACKAGE_VERSION, and the schema generator writes SCHEMA_VERSION into every
``$id`` under ``schemas/``.
"""

PACKAGE_VERSION = "0.1.0"
SPEC_VERSION = "1.0"
SCHEMA_VERSION = "1.0.0"
SCHEMA_BASE_URI = "https://haptify.org/schemas"


def schema_id(name: str) -> str:
    """The ``$id`` of schema ``name`` (e.g. ``"session"``) for the current spec version."""
    return f"{SCHEMA_BASE_URI}/{SPEC_VERSION}/{name}.schema.json"
