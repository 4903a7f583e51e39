"""Where a session's files are (spec §3.3, §3.4): the manifest's name, paths resolved inside the session folder
without ever leaving it, and the sha256 of a file's bytes.
"""

from __future__ import annotations

import hashlib
import os
from pathlib import Path, PurePosixPath

from haptify.codes import Code
from haptify.errors import Finding, HaptifyError
from haptify.formats.session_format import is_safe_relative_path

MANIFEST = "session.json"
MAX_SYMLINK_HOPS = 40  # as POSIX SYMLOOP_MAX
HASH_CHUNK = 1 << 20


def sha256_file(path: Path) -> str:
    """Hex sha256 of a file's bytes (spec §3.4)."""
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for chunk in iter(lambda: fh.read(HASH_CHUNK), b""):
            h.update(chunk)
    return h.hexdigest()


def resolve_inside(root: Path, relative: str, *, label: str | None = None) -> Path:
    """The path of ``relative`` inside ``root`` with every symbolic link resolved lexically (spec §3.3).

    Each component is examined with ``lstat`` inside the folder; a link's target is read with
    ``readlink`` and resolved against the folder, never against the file system, so nothing outside
    ``root`` is ever touched. Raises E108 for an unsafe declared path, E109 when a link leads out.
    """
    label = label or relative
    if not is_safe_relative_path(relative):
        raise HaptifyError(
            Finding(
                Code.UNSAFE_PATH,
                f"path {relative!r} is absolute or leaves the session folder",
                file=label,
                expected="a relative POSIX path inside the session folder",
                found=relative,
            )
        )
    current: list[str] = []
    pending = relative.split("/")
    hops = 0
    link = last_target = ""

    def escape(target: str) -> HaptifyError:
        return HaptifyError(
            Finding(
                Code.SYMLINK_ESCAPE,
                f"{relative!r} passes through the symbolic link {link!r} → {target!r}, which leads outside the session folder",
                file=label,
                expected="a link target inside the session folder",
                found=target,
            )
        )

    while pending:
        part = pending.pop(0)
        if part in ("", "."):
            continue
        if part == "..":
            if not current:
                raise escape(last_target)
            current.pop()
            continue
        candidate = root.joinpath(*current, part)
        if candidate.is_symlink():
            hops += 1
            link = "/".join([*current, part])
            last_target = os.readlink(candidate)
            if hops > MAX_SYMLINK_HOPS or PurePosixPath(last_target).is_absolute() or "\\" in last_target:
                raise escape(last_target)
            pending = last_target.split("/") + pending
            continue
        current.append(part)
    return root.joinpath(*current)
