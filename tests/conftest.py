"""Shared test helpers: paths and small sessions."""

from __future__ import annotations

from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
SHARED = REPO.parent / "shared"


@pytest.fixture
def example_session(tmp_path: Path) -> Path:
    """A small valid analytic free-space session (Parquet)."""
    from haptify_tools.example_session import write_example

    return write_example(tmp_path / "example")
