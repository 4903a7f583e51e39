"""Access to the normative JSON data shipped in ``schemas/`` (spec §0.3): the reference reads it through
the data package's own loader (``haptify_schemas``), as the conformance judge does."""

from haptify_schemas import list_dir, load, schema

__all__ = ["list_dir", "load", "schema"]
