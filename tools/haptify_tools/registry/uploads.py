"""Resumable chunked uploads (spec §17.5.2): a large bundle is sent in chunks that are appended to a file in
``DATA/uploads/``, so a dropped connection loses only the chunk in flight — the client asks how far the
registry got and continues from there — and the archive is never held in memory.

1. ``POST /api/v1/uploads`` with ``Upload-Length: N`` opens an upload of N bytes (E960 when N is over
   ``max_archive_bytes``);
2. ``PATCH /api/v1/uploads/{id}`` with ``Upload-Offset: k`` appends its body at byte k, which must be the
   bytes received so far (E975 otherwise, naming them); the bytes of a body cut short are kept;
3. ``GET /api/v1/uploads/{id}`` says the offset reached;
4. ``POST /api/v1/uploads/{id}/submit`` submits the complete archive exactly as ``POST /submissions``.

Uploads belong to the token that opened them and live on disk, so they survive a restart of the
registry: ``<id>.part`` holds the bytes, ``<id>.json`` the owner, the declared length, the offset up to
which the part file is fsynced and the time of the last chunk (written atomically after each chunk's
fsync). A new process on the same data folder resumes every upload at its recorded offset (a part file
longer than that — a chunk torn by a crash — is cut back). An upload without a chunk for ``ttl_s``
(``Settings.upload_ttl_s``, default 24 h) expires: it is deleted at start-up and whenever an upload is
opened or looked up.
"""

from __future__ import annotations

import json
import os
import re
import secrets
import threading
import time
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import AsyncIterator

from starlette.concurrency import run_in_threadpool
from starlette.requests import ClientDisconnect

from haptify.codes import Code
from haptify.errors import fail
from haptify.formats.storage import atomic_write_text
from haptify_tools.registry.bundle import DIR_MODE, FILE_MODE

UPLOAD_TTL_S = 24 * 3600.0
UPLOAD_ID = re.compile(r"^[0-9a-f]{24}$")  # secrets.token_hex(12): nothing else names a file here


@dataclass
class Upload:
    """One upload in progress: its owner (token id), declared length, bytes received (fsynced) and the
    wall-clock time of its last chunk (s since the epoch)."""

    id: str
    token_id: int
    length: int
    offset: int = 0
    touched: float = 0.0
    busy: bool = False

    def state(self) -> dict:
        return {
            "id": self.id,
            "offset": self.offset,
            "length": self.length,
            "complete": self.offset == self.length,
            "url": f"/api/v1/uploads/{self.id}",
        }


class Uploads:
    """The uploads in progress of one registry, kept in ``folder`` (thread-safe; one process per data folder)."""

    def __init__(self, folder: Path, tmp: Path, max_bytes: int, ttl_s: float = UPLOAD_TTL_S) -> None:
        self.folder, self.tmp, self.max_bytes, self.ttl_s = folder, tmp, max_bytes, ttl_s
        self._lock = threading.Lock()
        self._open: dict[str, Upload] = {}
        self.folder.mkdir(mode=DIR_MODE, parents=True, exist_ok=True)
        self.resumed, self.expired = self._load()

    # --- files -------------------------------------------------------------------------------------
    def _part(self, uid: str) -> Path:
        return self.folder / f"{uid}.part"

    def _record(self, uid: str) -> Path:
        return self.folder / f"{uid}.json"

    def _save(self, upload: Upload) -> None:
        """The upload's record, written atomically (mode 0600) after its bytes are fsynced."""
        record = {k: v for k, v in asdict(upload).items() if k != "busy"}
        atomic_write_text(self._record(upload.id), json.dumps(record) + "\n")
        os.chmod(self._record(upload.id), FILE_MODE)

    def _delete(self, uid: str) -> None:
        self._part(uid).unlink(missing_ok=True)
        self._record(uid).unlink(missing_ok=True)

    def _load(self) -> tuple[int, int]:
        """Take over the uploads a previous process left: each record with its part file, cut back to the
        recorded offset. Expired uploads, and halves (a part without a record or the reverse), are deleted.
        Returns (resumed, deleted)."""
        resumed = deleted = 0
        now = time.time()
        names = {p.name.rsplit(".", 1)[0] for p in self.folder.iterdir() if p.suffix in (".part", ".json")}
        for uid in sorted(names):
            try:
                rec = json.loads(self._record(uid).read_text(encoding="utf-8"))
                upload = Upload(uid, int(rec["token_id"]), int(rec["length"]), int(rec["offset"]), float(rec["touched"]))
                size = self._part(uid).stat().st_size
            except (OSError, ValueError, KeyError, TypeError):
                upload, size = None, -1
            if upload is None or not UPLOAD_ID.match(uid) or size < upload.offset or now - upload.touched > self.ttl_s:
                self._delete(uid)
                deleted += 1
                continue
            if size > upload.offset:  # a chunk torn by the crash: its unacknowledged bytes are dropped
                os.truncate(self._part(uid), upload.offset)
            self._open[uid] = upload
            resumed += 1
        return resumed, deleted

    def _expire(self) -> None:
        now = time.time()
        for u in [u for u in self._open.values() if not u.busy and now - u.touched > self.ttl_s]:
            self._open.pop(u.id)
            self._delete(u.id)

    # --- the protocol ------------------------------------------------------------------------------
    def open(self, token_id: int, length: str | None) -> Upload:
        """Start an upload of ``length`` bytes (the ``Upload-Length`` header)."""
        if length is None or not length.isdigit() or int(length) == 0:
            raise fail(
                Code.REQUEST_INVALID,
                "an upload needs its total size",
                file="Upload-Length",
                expected="a positive byte count",
                found=length,
            )
        if int(length) > self.max_bytes:
            raise fail(
                Code.BUNDLE_TOO_LARGE,
                "the bundle archive is larger than the registry accepts",
                file="Upload-Length",
                expected=f"≤ {self.max_bytes} bytes",
                found=f"{length} bytes",
            )
        uid = secrets.token_hex(12)
        os.close(os.open(self._part(uid), os.O_WRONLY | os.O_CREAT | os.O_EXCL, FILE_MODE))
        upload = Upload(uid, token_id, int(length), touched=time.time())
        self._save(upload)
        with self._lock:
            self._expire()
            self._open[uid] = upload
        return upload

    def get(self, uid: str, token_id: int | None = None) -> Upload:
        """The upload ``uid`` (E973 unknown or expired; E971 another token's)."""
        with self._lock:
            self._expire()
            upload = self._open.get(uid) if UPLOAD_ID.match(uid) else None
        if upload is None:
            raise fail(
                Code.NOT_FOUND, f"no upload {uid[:40]!r} in progress", expected="an id from POST /api/v1/uploads", found=uid[:40]
            )
        if token_id is not None and upload.token_id != token_id:
            raise fail(Code.TOKEN_SCOPE, "an upload is continued by the token that opened it", file="Authorization")
        return upload

    async def append(self, uid: str, token_id: int, offset: str | None, chunks: AsyncIterator[bytes]) -> Upload:
        """Append a request body at ``offset`` (the ``Upload-Offset`` header), streamed to disk. A body cut
        short by a dropped connection keeps what arrived; the next chunk continues from there."""
        upload = self.get(uid, token_id)
        with self._lock:
            if upload.busy:
                raise fail(
                    Code.REQUEST_INVALID,
                    "a chunk of this upload is being received",
                    file="Upload-Offset",
                    expected="one chunk at a time",
                    found="concurrent chunk",
                )
            if offset is None or not offset.isdigit() or int(offset) != upload.offset:
                raise fail(
                    Code.REQUEST_INVALID,
                    f"the chunk does not start where the upload stands ({upload.offset} bytes received)",
                    file="Upload-Offset",
                    expected=upload.offset,
                    found=offset,
                )
            upload.busy = True
        received = upload.offset
        try:
            with open(self._part(uid), "r+b") as fh:
                fh.seek(received)
                try:
                    async for chunk in chunks:
                        if received + len(chunk) > upload.length:
                            raise fail(
                                Code.BUNDLE_TOO_LARGE,
                                "the chunk goes past the declared length of the upload",
                                file="<upload>",
                                expected=f"≤ {upload.length} bytes",
                                found=f"> {upload.length} bytes",
                            )
                        fh.write(chunk)
                        received += len(chunk)
                except ClientDisconnect:  # keep what arrived: the client resumes from upload.offset
                    pass
                finally:
                    fh.flush()
                    await run_in_threadpool(os.fsync, fh.fileno())
                    upload.offset, upload.touched = received, time.time()
                    await run_in_threadpool(self._save, upload)
        finally:
            upload.busy = False
        return upload

    def take(self, uid: str, token_id: int) -> Path:
        """The complete archive of an upload, moved to ``tmp/`` for a submission (the upload ends here)."""
        upload = self.get(uid, token_id)
        with self._lock:
            if upload.busy or upload.offset != upload.length:
                raise fail(
                    Code.REQUEST_INVALID,
                    "the upload is not complete",
                    file="<upload>",
                    expected=f"{upload.length} bytes",
                    found=f"{upload.offset} bytes",
                )
            self._open.pop(uid)
        self.tmp.mkdir(mode=DIR_MODE, parents=True, exist_ok=True)
        final = self.tmp / f"upload-{uid}.tar.gz"
        os.replace(self._part(uid), final)
        self._record(uid).unlink(missing_ok=True)
        return final


__all__ = ["Uploads", "Upload", "UPLOAD_TTL_S"]
