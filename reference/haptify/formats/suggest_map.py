"""A map to start from (spec §5.11): an import map guessed from a source's labels, body names, platforms
and column headers, with every fact the source cannot hold left as a ``<…>`` placeholder (which the map
schema refuses until the lab fills it in), and a list of what could not be placed.

The guesses are rules on names, written as data (``CHANNEL_RULES``), never a fact about the recording:
the lab reads, edits and keeps the map.
"""

from __future__ import annotations

import csv
import re
from pathlib import Path
from typing import AbstractSet, Any

from haptify.formats.importers import UNITS, C3DPlatform, Recording, sanitize_id
from haptify.processing.platform_wrench import CHANNEL_DIMENSIONS, PLATFORM_CHANNELS

PLACEHOLDER_SESSION = {
    "date": "<YYYY-MM-DD, or --date per file>",
    "lab": {"id": "<lab id>"},
    "examiner": {"id": "<examiner id>"},
    "device": {"file": "<device.json>"},
    "device_placement": {"position": ["<x m>", "<y m>", "<z m>"], "quaternion": [1.0, 0.0, 0.0, 0.0]},
}
PLACEHOLDER_TRIAL = {"protocol": "other", "powered": "<true or false>"}

# (stream kind, column, pattern on a label with spaces/_/- removed, lower case); first match wins.
CHANNEL_RULES: list[tuple[str, str, str]] = [
    ("sync", "trigger", r"(sync|trig(ger)?)"),
    *[("handle_accel", f"a{ax}", rf"acc(el(erometer)?)?{ax}$") for ax in "xyz"],
    *[("plate_wrench", f"c{c}_f{ax}", rf"c(orner)?{c}f{ax}$") for c in "1234" for ax in "xyz"],
    *[("plate_wrench", f"c{c}_t{ax}", rf"c(orner)?{c}[mt]{ax}$") for c in "1234" for ax in "xyz"],
    *[("handle_wrench", f"{q}{ax}", rf"^{q}{ax}$" if q == "f" else rf"^[mt]{ax}$") for q in "ft" for ax in "xyz"],
    *[("commanded_wrench", f"{q}{ax}", rf"cmd{q}{ax}$|command(ed)?{q}{ax}$") for q in "ft" for ax in "xyz"],
    *[("device_joint_angles", f"q{i}", rf"^(q|joint){i}$") for i in range(1, 7)],
]
HANDLE_BODY = re.compile(r"handle|stylus|pen|tool|end.?effector", re.IGNORECASE)
LINK_BODY = re.compile(r"link\s*(\d+)", re.IGNORECASE)
TIME_COLUMN = re.compile(r"^(t|time|timestamp)\b", re.IGNORECASE)


def _key(label: str) -> str:
    """A label without its unit in parentheses, separators and case: 'Fx (N)' → 'fx'."""
    return re.sub(r"[\s_\-:.\[\]]", "", re.sub(r"\(.*?\)", "", label)).lower()


def guess_streams(labels: list[str], skip: AbstractSet[str] = frozenset()) -> tuple[dict[str, dict[str, str]], list[str]]:
    """Stream kind → {column: label} for the labels the rules place; the labels left over."""
    streams: dict[str, dict[str, str]] = {}
    left = []
    for label in labels:
        if label in skip:
            continue
        key = _key(label)
        for kind, column, pattern in CHANNEL_RULES:
            if re.search(pattern, key) and column not in streams.get(kind, {}):
                streams.setdefault(kind, {})[column] = label
                break
        else:
            left.append(label)
    return streams, left


def _complete(streams: dict[str, dict[str, Any]], unplaced: list[str]) -> dict[str, dict[str, Any]]:
    """Keep only streams whose every column was placed; the rest go to ``unplaced``."""
    from haptify.formats.session_format import expected_columns

    out = {}
    for kind, cols in streams.items():
        need = [c for c, _ in expected_columns(kind, present=list(cols))][1:]
        if all(c in cols for c in need):
            out[kind] = cols
        else:
            unplaced.append(
                f"{kind}: only {sorted(cols)} found ({', '.join(cols.values())}); "
                f"it needs {need} — map the rest or leave the stream out"
            )
    return out


def _wrench_units_known(rec: Recording, platform: C3DPlatform) -> bool:
    """Whether a platform's channels state the units its type's outputs need (§5.6.1), so that
    ``platform_wrench: {}`` imports it as written."""
    if platform.type is None:  # no TYPE: no outputs whose units could be known
        return False
    dims = CHANNEL_DIMENSIONS.get(platform.type)
    chans = platform.channels[: PLATFORM_CHANNELS.get(platform.type, 0)]
    if dims is None or len(chans) < len(dims) or (platform.type == 4 and platform.cal_matrix is None):
        return False
    units = [UNITS.get(rec.analog_units[i].strip()) for i in chans]
    return all(u is not None and u.dimension == d for u, d in zip(units, dims))


def suggest_recording_map(rec: Recording) -> tuple[dict[str, Any], list[str]]:
    """A map for a motion-capture recording (C3D, TSV, Motive, Nexus) and the notes on what it could not place."""
    unplaced: list[str] = []
    m: dict[str, Any] = {"source": rec.format, "session": dict(PLACEHOLDER_SESSION), "trial": dict(PLACEHOLDER_TRIAL)}
    if rec.point_labels:
        m["markers"] = {"include": list(rec.point_labels)}
        renamed = {lab: sanitize_id(lab, f"m{i + 1}") for i, lab in enumerate(rec.point_labels)}
        unplaced.append(
            "markers: every point label is imported; which markers form a link's rigid body "
            f"(markers.rigid_bodies) is not in the file ({len(renamed)} ids, e.g. {list(renamed.values())[:3]})"
        )
    bodies: dict[str, Any] = {}
    for label in rec.body_labels:
        link = LINK_BODY.search(label)
        if HANDLE_BODY.search(label) and "handle" not in bodies:
            bodies["handle"] = label
        elif link:
            bodies.setdefault("links", {})[f"link{link.group(1)}"] = label
            unplaced.append(f"body {label!r} → link{link.group(1)}: add that link to markers.rigid_bodies (§2.4)")
        else:
            unplaced.append(f"6-DoF body {label!r}: neither the handle nor a numbered link by its name")
    if bodies:
        m["bodies"] = bodies
    platform_channels: set[str] = set()
    if rec.platforms:
        m["force_plate"] = 1
        for p in rec.platforms:
            names = [rec.analog_labels[i] for i in p.channels if i < len(rec.analog_labels)]
            platform_channels.update(names)
            if p.number == 1 and _wrench_units_known(rec, p):
                m["platform_wrench"] = {}
                unplaced.append(
                    f"force platform 1 (type {p.type}) defines W and its channels {names} become "
                    "plate_wrench (§5.6.1): check their units"
                )
            else:
                unplaced.append(
                    f"force platform {p.number} (type {p.type}): channels {names} not imported — "
                    + (
                        "platform 1 defines W; give platform_wrench with its output units to import its wrench"
                        if p.number == 1
                        else "the rig holds one plate (§5.5)"
                    )
                )
    elif rec.point_labels or rec.body_labels:
        m["lab_to_world"] = {"position": [0.0, 0.0, 0.0], "quaternion": [1.0, 0.0, 0.0, 0.0]}
        unplaced.append(
            "lab_to_world: the file has no force platform; the identity keeps W = the lab frame — give the lab frame's pose in W"
        )
    streams, left = guess_streams(rec.analog_labels, platform_channels)
    streams = _complete(streams, unplaced)
    if streams:
        m["streams"] = {
            kind: {"columns": {c: _channel(kind, c, lab) for c, lab in cols.items()}} for kind, cols in streams.items()
        }
        if "sync" in streams:
            unplaced.append("sync: threshold 2.5 (V) assumed for a 0–5 V trigger; check the level")
    unplaced += [f"analog channel {lab!r}: no stream by its name" for lab in left]
    return m, unplaced


def _channel(kind: str, column: str, label: str) -> dict[str, Any] | str:
    return {"source": label, "threshold": 2.5} if kind == "sync" else label


def suggest_csv_map(path: Path) -> tuple[dict[str, Any], list[str]]:
    """A map for a CSV log (§5.7): the header after any preamble, a time column by its name, streams by
    the column rules; every unit is a placeholder, because CSV columns state none."""
    with open(path, encoding="utf-8", newline="") as fh:
        lines = [line for line in (fh.readline() for _ in range(50)) if line.strip()]
    # the delimiter that splits the most lines into the same number (> 1) of fields; the header is
    # the first line with that many (the lines before it are the preamble)
    counts = {d: [len(next(csv.reader([line], delimiter=d))) for line in lines] for d in ",;\t"}
    delimiter = max(counts, key=lambda d: max((counts[d].count(n) for n in set(counts[d]) if n > 1), default=0))
    width = max(set(counts[delimiter]), key=counts[delimiter].count) if lines else 0
    skip = counts[delimiter].index(width) if lines else 0
    header = [h.strip() for h in next(csv.reader([lines[skip]], delimiter=delimiter))] if lines else []
    unplaced: list[str] = []
    time = next((h for h in header if TIME_COLUMN.search(h)), None)
    if time is None:
        unplaced.append(f"time: no column named like a time among {header}")
    unit = re.search(r"\((s|ms|us)\)|_(s|ms|us)$", time or "")
    m: dict[str, Any] = {
        "source": "csv",
        "session": dict(PLACEHOLDER_SESSION),
        "trial": dict(PLACEHOLDER_TRIAL),
        "time": {"source": time or "<time column>", "unit": next((g for g in unit.groups() if g), "s") if unit else "<s|ms|us>"},
        "csv": {"delimiter": delimiter, "skip_rows": skip},
    }
    streams, left = guess_streams([h for h in header if h != time])
    streams = _complete(streams, unplaced)
    m["streams"] = {
        kind: {
            "columns": {
                c: {"source": lab, "unit": _stated_unit(lab)}
                if kind != "sync"
                else {"source": lab, "unit": "V", "threshold": 2.5}
                for c, lab in cols.items()
            }
        }
        for kind, cols in streams.items()
    }
    unplaced += [f"column {h!r}: no stream by its name" for h in left]
    if any(ch.get("unit") == "<unit>" for st in m["streams"].values() for ch in st["columns"].values()):
        unplaced.append("units: a CSV states none; replace every '<unit>' (§5.3)")
    return m, unplaced


def _stated_unit(header: str) -> str:
    """The unit a header names in parentheses when it is in the table of §5.3 ('Tx (N-mm)' → 'N-mm')."""
    found = re.search(r"\(([^)]*)\)", header)
    return found.group(1).strip() if found and found.group(1).strip() in UNITS else "<unit>"
