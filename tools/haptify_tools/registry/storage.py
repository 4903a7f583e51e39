"""Where re-verification workers read the registry's bundle archives from (spec §17.9).

A store turns an archive's key — the ``archive_path`` of its record, ``bundles/<d₀d₁>/<digest>.tar.gz`` —
into a local file the worker can unpack. The registry writes archives to its data folder (spec §17.7), so
the one store today is that folder, read in place (:class:`LocalFolderStore`); on a cluster every worker
must see it at the path given (a network file system mounted read-only on the workers).

An object store slots in as another class with the same :meth:`materialize`: download the key into the
worker's scratch folder ``work`` and return that file. Keys are content addresses, so a downloaded
archive can be checked against the record's ``archive_sha256`` and cached by key without invalidation.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Protocol

from haptify.codes import Code
from haptify.errors import fail
from haptify.formats.storage import resolve_inside


class BundleStore(Protocol):
    """What a worker needs from the registry's storage: one archive as a local file (spec §17.9)."""

    @property
    def location(self) -> str:
        """Where the store is, as the workers see it (a folder path today)."""
        ...

    def materialize(self, key: str, work: Path) -> Path:
        """The archive ``key`` as a local file (inside ``work`` when it had to be fetched); E978 when missing."""
        ...


@dataclass(frozen=True)
class LocalFolderStore:
    """The registry's data folder, read in place (spec §17.7, §17.9); ``location`` as the workers see it."""

    location: str

    def materialize(self, key: str, work: Path) -> Path:
        path = resolve_inside(Path(self.location), key, label=key)
        if not path.is_file():
            raise fail(
                Code.REGISTRY_UNAVAILABLE,
                f"the archive {key!r} is not in the bundle store {self.location!r}",
                file=key,
                expected="the archive of an accepted submission",
                found="missing",
            )
        return path


def open_store(location: str) -> BundleStore:
    """The store at ``location``: a folder path or a ``file://`` URL (spec §17.9). Other schemes (an object
    store) are E903: none is implemented yet."""
    if location.startswith("file://"):
        location = location[len("file://") :]
    scheme = location.split("://", 1)[0] if "://" in location else None
    if scheme is not None:
        raise fail(
            Code.USAGE, f"no bundle store for {scheme}:// locations", expected="a folder path or file:// URL", found=location
        )
    return LocalFolderStore(str(Path(location).resolve()))
