"""Atomic writes (spec §3.6): a file written beside its target and renamed onto it, a folder moved into place."""

from __future__ import annotations

import json
import os
import shutil
import tempfile
import uuid
from pathlib import Path
from typing import Any, Callable

from haptify.codes import Code
from haptify.errors import fail


def write_atomically(path: Path, writer: Callable[[str], Any]) -> None:
    """Run ``writer(tmp_path)`` on a temporary file beside ``path``, then rename it onto ``path`` (spec §3.6).

    An exception (or an interruption) leaves ``path`` as it was and removes the temporary file.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp" + path.suffix, dir=path.parent)
    os.close(fd)
    try:
        writer(tmp)
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def atomic_write_text(path: Path, text: str) -> None:
    """Write a text file atomically, flushed to disk before the rename (spec §3.6)."""

    def write(tmp: str) -> None:
        with open(tmp, "w", encoding="utf-8") as fh:
            fh.write(text)
            fh.flush()
            os.fsync(fh.fileno())

    write_atomically(path, write)


def atomic_write_json(path: Path, payload: Any) -> None:
    """Write ``payload`` as UTF-8 JSON (2-space indent, final newline) atomically (spec §3.6; via :func:`atomic_write_text`)."""
    atomic_write_text(path, json.dumps(payload, indent=2, ensure_ascii=False) + "\n")


def replace_folder_atomically(build: Path, target: Path, overwrite: bool) -> None:
    """Move a fully written ``build`` folder to ``target`` (E901 when it exists and not ``overwrite``).
    Spec §3.6."""
    if target.exists():
        if not overwrite:
            shutil.rmtree(build, ignore_errors=True)
            raise fail(Code.OUTPUT_EXISTS, f"{str(target)!r} already exists", file=str(target))
        old = target.parent / f".{target.name}.old-{uuid.uuid4().hex[:8]}"
        os.replace(target, old)
        os.replace(build, target)
        shutil.rmtree(old, ignore_errors=True)
    else:
        os.replace(build, target)
