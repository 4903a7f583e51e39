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


def pytest_collection_modifyitems(items):
    """The longest test (``slow(longest=True)``) first, then the other ``slow`` ones: with ``-n 2 --dist worksteal``
    the longest then starts at once on one worker while the other takes the rest (stealing what the first has not
    started), instead of starting last and running alone at the end."""

    def rank(item) -> int:
        slow = item.get_closest_marker("slow")
        return 2 if slow is None else (0 if slow.kwargs.get("longest") else 1)

    items.sort(key=rank)
