"""Column-mapped CSV logs (spec §5.7): an ATI-style F/T log, a CHAI3D log of commanded force; one time
column serves every mapped stream."""

from __future__ import annotations

from pathlib import Path
from typing import Any, Literal, TypedDict

import numpy as np
import pandas as pd

from haptify.codes import Code
from haptify.errors import fail
from haptify.formats.importers.destination import Destination, ImportResult, add_trial, prepare
from haptify.formats.importers.import_map import CsvOptions, LoadedMap
from haptify.formats.importers.streams import as_channel, check_trial_streams, mapped_streams
from haptify.formats.importers.units import unit_conversion
from haptify.versions import PACKAGE_VERSION

RATE_SIGNIFICANT_DIGITS = 6  # a CSV stream's default nominal rate: 1/median(Δt) to 6 significant digits


def _round_significant(x: float, digits: int) -> float:
    return float(f"{x:.{digits}g}")


class _CsvReading(TypedDict, total=False):
    """The options :func:`read_csv_columns` gives pandas' ``read_csv``."""

    sep: str
    skiprows: int
    comment: str | None
    skipinitialspace: bool
    engine: Literal["c"]
    encoding: str
    usecols: list[str]
    na_values: list[str]
    keep_default_na: bool


def read_csv_columns(path: Path, names: list[str], opts: CsvOptions, *, map_label: str) -> dict[str, np.ndarray]:
    """The named columns of a CSV log as float64 arrays (spec §5.7).

    E501 when the file is missing or unreadable or a cell is not a number (row named); E503 when a
    column is not in the header (the header is listed).
    """
    label = str(path)
    if not path.is_file():
        raise fail(Code.IMPORT_SOURCE_UNREADABLE, f"{label!r} does not exist or is not a file", file=label)
    common: _CsvReading = {
        "sep": opts.delimiter,
        "skiprows": opts.skip_rows,
        "comment": opts.comment,
        "skipinitialspace": True,
        "engine": "c",
        "encoding": "utf-8",
    }
    try:
        raw_header = [str(h) for h in pd.read_csv(path, nrows=0, **common).columns]
    except (OSError, UnicodeDecodeError, pd.errors.ParserError, pd.errors.EmptyDataError, ValueError) as exc:
        raise fail(Code.IMPORT_SOURCE_UNREADABLE, f"{label!r} cannot be read as CSV: {exc}", file=label) from None
    header = [h.strip() for h in raw_header]
    for name in names:
        if name not in header:
            raise fail(
                Code.IMPORT_CHANNEL_UNKNOWN, f"{path.name} has no column {name!r}", file=map_label, expected=header, found=name
            )
    columns = {raw_header[header.index(name)]: name for name in names}
    numeric: _CsvReading = {"usecols": list(columns), "na_values": ["NaN", "nan"], "keep_default_na": False, **common}
    try:  # the fast path: the C parser, correctly rounded (pandas ≥ 3)
        table = pd.read_csv(path, dtype={c: "float64" for c in columns}, **numeric)
    except (OSError, UnicodeDecodeError, pd.errors.ParserError) as exc:
        raise fail(Code.IMPORT_SOURCE_UNREADABLE, f"{label!r} cannot be read as CSV: {exc}", file=label) from None
    except ValueError:  # some cell is not a number: find it for the message
        text = pd.read_csv(path, dtype=str, **numeric)
        first_data_line = opts.skip_rows + 2  # 1-based line of the first data row (comment lines aside)
        for raw_name, name in columns.items():
            cells = text[raw_name].fillna("").str.strip()
            parsed = pd.to_numeric(cells, errors="coerce")
            bad = np.flatnonzero(parsed.isna() & ~cells.str.lower().isin(["nan"]))
            if bad.size:
                i = int(bad[0])
                raise fail(
                    Code.IMPORT_SOURCE_UNREADABLE,
                    f"{path.name} column {name!r}, data row {i + 1} (line ≈{first_data_line + i}) is not a number",
                    file=label,
                    column=name,
                    expected="a number",
                    found=cells.iloc[i],
                ) from None
        raise fail(Code.IMPORT_SOURCE_UNREADABLE, f"{label!r} cannot be read as numbers", file=label) from None
    return {name: table[raw].to_numpy(dtype=np.float64) for raw, name in columns.items()}


def import_csv(
    path: str | Path,
    out: str | Path | Destination,
    mapping: str | Path | LoadedMap,
    *,
    overrides: dict[str, Any] | None = None,
    overwrite: bool = False,
    append: bool = False,
) -> ImportResult:
    """Import a column-mapped CSV log as one trial of a new session at ``out`` (spec §5.7), or append
    it as one more trial to the session at ``out`` (``append``, §5.9).

    One time column (s, ms or us, plus ``time_offset_s``) serves every mapped stream; each column is
    converted to SI by §5.3. Nothing is written when any check fails.
    """
    dest, loaded, _, device, extra = prepare(out, mapping, "csv", overrides, overwrite, append)
    m, label = loaded.map, loaded.label
    src_path = Path(path)
    src = str(src_path)
    if not m.streams:
        raise fail(
            Code.IMPORT_MAP_INVALID,
            "a csv map needs at least one stream",
            file=label,
            pointer="/streams",
            expected="streams",
            found={},
        )
    opts = m.csv or CsvOptions()
    time = m.time
    assert time is not None  # load_map requires 'time' of a csv map (E502)
    sources = {as_channel(c).source for s in m.streams.values() for c in s.columns.values()}
    wanted = [time.source] + sorted({named for named in sources if named is not None} - {time.source})
    data = read_csv_columns(src_path, wanted, opts, map_label=label)
    time_unit = unit_conversion(time.unit, "s", file=label, pointer="/time/unit", column=time.source)
    t = time_unit.to_si(data[time.source])
    if m.time_offset_s != 0.0:
        t = t + m.time_offset_s
    if t.size < 2:
        raise fail(
            Code.STREAM_EMPTY,
            f"{src_path.name} holds {t.size} row(s); a stream needs two",
            file=src,
            expected="≥ 2 rows",
            found=int(t.size),
        )
    steps = np.diff(t)
    if not np.isfinite(t).all() or (steps <= 0).any():
        i = int(np.argmax(~np.isfinite(t))) if not np.isfinite(t).all() else int(np.argmax(steps <= 0)) + 1
        raise fail(
            Code.TIME_NOT_INCREASING,
            f"time column {time.source!r} of {src_path.name} is not finite and strictly increasing at data row {i + 1}",
            file=src,
            column=time.source,
            expected="strictly increasing",
            found=f"{data[time.source][i - 1] if i else ''} → {data[time.source][i]}",
        )

    def read(name: str) -> tuple[np.ndarray, str | None]:
        return data[name], None

    streams = mapped_streams(m, t.size, read, label=label, source_file=src, unit_required=True)
    check_trial_streams(m, list(streams), label)
    rig = dest.rig(m.session.rig.model_dump(mode="json", exclude_none=True), None, label)
    writer, stem = dest.writer(m, src_path, rig, device, extra, f"haptify {PACKAGE_VERSION} import csv")
    trial_id = add_trial(writer, m, stem, src_path, f"Imported from {src_path.name} by haptify {PACKAGE_VERSION}.")
    default_rate = _round_significant(1.0 / float(np.median(steps)), RATE_SIGNIFICANT_DIGITS)
    written = []
    for kind, cols in streams.items():
        smap = m.streams[kind]
        written.append(
            writer.add_stream(
                trial_id, kind, {"t": t, **cols}, rate_hz=smap.rate_hz or default_rate, fmt=smap.format, frame=smap.frame
            )
        )
    return dest.finish(
        writer,
        trial_id,
        written,
        "CSV values are stored as logged (rotated into W only where from_frame says so)",
        {"file": src_path.name, "rows": int(t.size), "columns": wanted},
    )
