"""The CSV stream grammar of spec §3.2, checked in bounded memory while the file's bytes are hashed."""

from __future__ import annotations

import hashlib
import re
from pathlib import Path

from haptify.codes import Code
from haptify.errors import fail
from haptify.formats.storage.json_documents import short_text

CSV_FIELD = re.compile(rb"(?<![^,\n])(?:NaN|-?[0-9]+(?:\.[0-9]*)?(?:[eE][+-]?[0-9]+)?)(?![^,\r\n])")
CSV_FIELD_TEXT = re.compile(r"NaN|-?[0-9]+(?:\.[0-9]*)?(?:[eE][+-]?[0-9]+)?")
CSV_CHUNK_BYTES = 8 * 2**20
CSV_FIELD_MAX_CHARS = 32  # the longest field §3.2 allows: 17 significant digits, sign, point, exponent


def csv_line_limit(columns: list[str]) -> int:
    """The longest line (bytes, line end included) a CSV stream with ``columns`` can hold (spec §3.2):
    ``n`` fields of at most :data:`CSV_FIELD_MAX_CHARS`, ``n − 1`` commas and CR LF — or the header's
    names, commas and line end when they are longer."""
    n = len(columns)
    names = sum(len(c.encode("utf-8")) for c in columns)
    return max(names, CSV_FIELD_MAX_CHARS * n) + n + 1


def check_csv_grammar(path: Path, columns: list[str], label: str) -> str:
    r"""Check a CSV stream against the grammar of spec §3.2 and return the sha256 of its bytes.

    The header must list ``columns`` (E211). Every line after it holds exactly ``len(columns)`` fields,
    each ``NaN`` or a decimal number ``-?[0-9]+(\.[0-9]*)?([eE][+-]?[0-9]+)?`` — no sign '+', quotes,
    spaces, empty fields, ``inf`` or blank lines — and ends in ``\n`` or ``\r\n`` (the last line's end
    optional); the first line that does not is E112. The file is scanned in chunks of whole lines (every
    valid field is replaced by ``x``, so a sound line reads ``x,x,…,x``); a line longer than
    :func:`csv_line_limit` is E112 as soon as it is seen, so memory stays bounded whatever the content.
    """
    sound = b",".join([b"x"] * len(columns))
    allowed = {sound, sound + b"\r"}
    limit = csv_line_limit(columns)
    digest = hashlib.sha256()
    with open(path, "rb") as fh:
        header = fh.readline(limit + 1)
        digest.update(header)
        _check_csv_header(header, columns, label, limit)
        line_no, rest = 1, b""
        while True:
            block = fh.read(CSV_CHUNK_BYTES)
            digest.update(block)
            data = rest + block
            if block:
                cut = data.rfind(b"\n") + 1
                data, rest = data[:cut], data[cut:]
                if len(rest) > limit:
                    long_line = line_no + data.count(b"\n") + 1
                    raise fail(
                        Code.STREAM_UNREADABLE,
                        f"line {long_line} of {label!r} is longer than the {limit} bytes "
                        f"a line of {len(columns)} numbers can take",
                        file=label,
                        expected=f"at most {limit} bytes per line",
                        found=f"more than {len(rest)} bytes",
                    )
            else:
                rest = b""
            if data:
                lines = CSV_FIELD.sub(b"x", data).split(b"\n")
                if data.endswith(b"\n"):
                    lines.pop()
                if not set(lines) <= allowed:
                    k = next(i for i, line in enumerate(lines) if line not in allowed)
                    _csv_line_error(data.split(b"\n")[k], line_no + k + 1, columns, label)
                line_no += len(lines)
            if not block:
                return digest.hexdigest()


def _check_csv_header(header: bytes, columns: list[str], label: str, limit: int) -> None:
    r"""The header line names exactly ``columns`` and ends in ``\n`` or ``\r\n`` (E211, E112; spec §3.2)."""
    if len(header) > limit:
        raise fail(
            Code.CSV_HEADER_MALFORMED,
            f"the header line of {label!r} is longer than the {limit} bytes its columns take",
            file=label,
            expected=columns,
            found=f"more than {limit} bytes",
        )
    body = header.removesuffix(b"\n").removesuffix(b"\r")
    if b"\r" in body:
        raise fail(
            Code.STREAM_UNREADABLE,
            f"{label!r} ends a line with a lone carriage return",
            file=label,
            expected="lines ending in \\n or \\r\\n",
            found="\\r",
        )
    found = body.decode("utf-8", errors="replace").split(",")
    if found != columns:
        raise fail(
            Code.CSV_HEADER_MALFORMED,
            f"CSV header of {label!r} differs from the declared columns",
            file=label,
            expected=columns,
            found=[short_text(f) for f in found[: len(columns) + 2]],
        )


def _csv_line_error(raw: bytes, line_no: int, columns: list[str], label: str) -> None:
    """Raise E112 naming the line, the column and the first field of ``raw`` outside the grammar."""
    text = raw.decode("utf-8", errors="replace").removesuffix("\r")
    fields = text.split(",")
    if text == "":
        raise fail(
            Code.STREAM_UNREADABLE,
            f"line {line_no} of {label!r} is blank",
            file=label,
            expected="one sample per line, no blank lines",
            found="a blank line",
        )
    if len(fields) != len(columns):
        raise fail(
            Code.STREAM_UNREADABLE,
            f"line {line_no} of {label!r} has {len(fields)} fields, not {len(columns)}",
            file=label,
            expected=len(columns),
            found=len(fields),
        )
    k = next((i for i, f in enumerate(fields) if not CSV_FIELD_TEXT.fullmatch(f)), 0)
    raise fail(
        Code.STREAM_UNREADABLE,
        f"line {line_no} of {label!r}: field {short_text(fields[k])!r} is not a number as spec §3.2 writes it",
        file=label,
        column=columns[k],
        expected="NaN or -?[0-9]+(.[0-9]*)?([eE][+-]?[0-9]+)?",
        found=short_text(fields[k]),
    )
