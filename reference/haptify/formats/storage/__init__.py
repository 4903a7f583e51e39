"""Session storage: folders, stream files, checksums and atomic writes (spec chapter 3).

Reading is lazy: :func:`open_session` parses and checks ``session.json`` only; each stream is read
when asked for. Writing goes through :class:`SessionWriter`, which writes the whole session into a
temporary sibling folder and renames it into place, so an interrupted write never leaves a half
session. Nothing outside the session folder is ever read or written (§3.3).

The package by concern: :mod:`.paths` (the manifest's name, paths inside the folder, checksums; §3.3, §3.4),
:mod:`.json_documents` (strict JSON and pydantic findings; §3.1, §4.6), :mod:`.csv_grammar` (§3.2),
:mod:`.stream_files` (reading and writing stream tables; §3.2), :mod:`.session_folder` (reading a session;
§3.1), :mod:`.atomic` (atomic writes; §3.6) and :mod:`.writer` (writing a session; §3.6). This module
re-exports their public names.
"""

from __future__ import annotations

from haptify.formats.storage.atomic import atomic_write_json, atomic_write_text, replace_folder_atomically, write_atomically
from haptify.formats.storage.csv_grammar import (
    CSV_CHUNK_BYTES,
    CSV_FIELD,
    CSV_FIELD_MAX_CHARS,
    CSV_FIELD_TEXT,
    check_csv_grammar,
    csv_line_limit,
)
from haptify.formats.storage.json_documents import parse_json_file, pointer_of, pydantic_findings, read_json_model
from haptify.formats.storage.paths import HASH_CHUNK, MANIFEST, MAX_SYMLINK_HOPS, resolve_inside, sha256_file
from haptify.formats.storage.session_folder import SessionFolder, open_session
from haptify.formats.storage.stream_files import (
    TableSink,
    arrow_frame,
    as_float64,
    read_stream_chunks,
    read_stream_file,
    read_table,
    write_table,
)
from haptify.formats.storage.writer import SessionWriter

__all__ = [
    "CSV_CHUNK_BYTES",
    "CSV_FIELD",
    "CSV_FIELD_MAX_CHARS",
    "CSV_FIELD_TEXT",
    "HASH_CHUNK",
    "MANIFEST",
    "MAX_SYMLINK_HOPS",
    "SessionFolder",
    "SessionWriter",
    "TableSink",
    "arrow_frame",
    "as_float64",
    "atomic_write_json",
    "atomic_write_text",
    "check_csv_grammar",
    "csv_line_limit",
    "open_session",
    "parse_json_file",
    "pointer_of",
    "pydantic_findings",
    "read_json_model",
    "read_stream_chunks",
    "read_stream_file",
    "read_table",
    "replace_folder_atomically",
    "resolve_inside",
    "sha256_file",
    "write_atomically",
    "write_table",
]
