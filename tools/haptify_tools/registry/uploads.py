"""Resumable chunked uploads (spec §17.5.2): a large bundle is sent in chunks that are appended to a file in
``DATA/tmp/``, so a dropped connection loses only the chunk in flight — the client asks how far the
registry got and continues from there — and the archive is never held in memory.

1. ``POST /api/v1/uploads`` with ``Upload-Length: N`` opens an upload of N bytes (E960 when N is over
   ``max_archive_bytes``);
2. ``PATCH /api/v1/uploads/{id}`` with ``Upload-Offset: k`` appends its body at byte k, which must be the
   bytes received so far (E975 otherwise, naming them); the bytes of a body cut short are kept;
3. ``GET /api/v1/uploads/{id}`` says the offset reached;
4. ``POST /api/v1/uploads/{id}/submit`` submits the complete archive exactly as ``POST /submissions``.

Uploads belong to the token that opened them, live in this process (the start-up sweep deletes their
files with the rest of ``tmp/``) and are dropped after ``UPLOAD_TTL_S`` without a chunk.
"""

from __future__ import annotations

import os
import secrets
import threading
import time
from dataclasses import dataclass
from pathlib import Path
from typing import AsyncIterator

from starlette.concurrency import run_in_threadpool
from starlette.requests import ClientDisconnect

from haptify.errors import fail
from haptify_tools.registry.bundle import DIR_MODE, FILE_MODE

UPLOAD_TTL_S = 24 * 3600.0


@dataclass
class Upload:
    """One upload in progress: its owner (token id), declared length, bytes received and file."""

    id: str
    token_id: int
    length: int
    path: Path
    offset: int = 0
    touched: float = 0.0
    busy: bool = False

    def state(self) -> dict:
        return {"id": self.id, "offset": self.offset, "length": self.length, "complete": self.offset == self.length,
                "url": f"/api/v1/uploads/{self.id}"}


class Uploads:
    """The uploads in progress of one registry (thread-safe)."""

    def __init__(self, tmp: Path, max_bytes: int) -> None:
        self.tmp, self.max_bytes = tmp, max_bytes
        self._lock = threading.Lock()
        self._open: dict[str, Upload] = {}

    def _expire(self) -> None:
        now = time.monotonic()
        for u in [u for u in self._open.values() if not u.busy and now - u.touched > UPLOAD_TTL_S]:
            self._open.pop(u.id)
            u.path.unlink(missing_ok=True)

    def open(self, token_id: int, length: str | None) -> Upload:
        """Start an upload of ``length`` bytes (the ``Upload-Length`` header)."""
        if length is None or not length.isdigit() or int(length) == 0:
            raise fail("E975", "an upload needs its total size", file="Upload-Length", expected="a positive byte count",
                       found=length)
        if int(length) > self.max_bytes:
            raise fail("E960", "the bundle archive is larger than the registry accepts", file="Upload-Length",
                       expected=f"≤ {self.max_bytes} bytes", found=f"{length} bytes")
        self.tmp.mkdir(mode=DIR_MODE, parents=True, exist_ok=True)
        uid = secrets.token_hex(12)
        path = self.tmp / f"upload-{uid}.part"
        os.close(os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL, FILE_MODE))
        with self._lock:
            self._expire()
            upload = self._open[uid] = Upload(uid, token_id, int(length), path, touched=time.monotonic())
        return upload

    def get(self, uid: str, token_id: int | None = None) -> Upload:
        """The upload ``uid`` (E973 unknown or expired; E971 another token's)."""
        with self._lock:
            upload = self._open.get(uid)
        if upload is None:
            raise fail("E973", f"no upload {uid!r} in progress", expected="an id from POST /api/v1/uploads", found=uid)
        if token_id is not None and upload.token_id != token_id:
            raise fail("E971", "an upload is continued by the token that opened it", file="Authorization")
        return upload

    async def append(self, uid: str, token_id: int, offset: str | None, chunks: AsyncIterator[bytes]) -> Upload:
        """Append a request body at ``offset`` (the ``Upload-Offset`` header), streamed to disk. A body cut
        short by a dropped connection keeps what arrived; the next chunk continues from there."""
        upload = self.get(uid, token_id)
        with self._lock:
            if upload.busy:
                raise fail("E975", "a chunk of this upload is being received", file="Upload-Offset",
                           expected="one chunk at a time", found="concurrent chunk")
            if offset is None or not offset.isdigit() or int(offset) != upload.offset:
                raise fail("E975", f"the chunk does not start where the upload stands ({upload.offset} bytes received)",
                           file="Upload-Offset", expected=upload.offset, found=offset)
            upload.busy = True
        try:
            with open(upload.path, "r+b") as fh:
                fh.seek(upload.offset)
                try:
                    async for chunk in chunks:
                        if upload.offset + len(chunk) > upload.length:
                            raise fail("E960", "the chunk goes past the declared length of the upload", file="<upload>",
                                       expected=f"≤ {upload.length} bytes", found=f"> {upload.length} bytes")
                        fh.write(chunk)
                        upload.offset += len(chunk)
                except ClientDisconnect:  # keep what arrived: the client resumes from upload.offset
                    pass
                finally:
                    fh.flush()
                    await run_in_threadpool(os.fsync, fh.fileno())
        finally:
            upload.busy, upload.touched = False, time.monotonic()
        return upload

    def take(self, uid: str, token_id: int) -> Path:
        """The complete archive of an upload, handed over to a submission (the upload ends here)."""
        upload = self.get(uid, token_id)
        with self._lock:
            if upload.busy or upload.offset != upload.length:
                raise fail("E975", "the upload is not complete", file="<upload>", expected=f"{upload.length} bytes",
                           found=f"{upload.offset} bytes")
            self._open.pop(uid)
        final = upload.path.with_suffix(".tar.gz")
        os.replace(upload.path, final)
        return final


__all__ = ["Uploads", "Upload", "UPLOAD_TTL_S"]
