"""Haptify reference implementation: read, validate and analyse Haptify 1.0 sessions.

The package follows the spec chapter by chapter (``spec/``); each module names the chapter it
implements. The normative data (schemas, metric definitions, code catalogue) is read through
:mod:`haptify.schemas`.
"""

from haptify.versions import PACKAGE_VERSION as __version__
from haptify.versions import SPEC_VERSION

__all__ = ["__version__", "SPEC_VERSION"]
