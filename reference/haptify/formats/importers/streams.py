"""Stream columns from source channels (spec §5.3): units, scale and offset, thresholds, the device
frame rotated into W (§5.2 ``from_frame``); the protocol's required streams (§2.5)."""

from __future__ import annotations

from typing import Callable

import numpy as np

from haptify import schemas
from haptify.codes import Code
from haptify.errors import fail
from haptify.formats.conventions import quat_to_matrix
from haptify.formats.importers.import_map import ChannelMap, ImportMap, StreamMap
from haptify.formats.importers.units import UNITS, unit_conversion
from haptify.formats.session_format import (
    ALLOWED_VALUES,
    Pose,
    expected_columns,
    kind_table,
    values_outside_set,
)

SourceReader = Callable[[str], tuple[np.ndarray, str | None]]


def as_channel(spec: ChannelMap | str) -> ChannelMap:
    return ChannelMap(source=spec) if isinstance(spec, str) else spec


def build_stream_columns(
    kind: str, smap: StreamMap, n: int, read: SourceReader, *, label: str, source_file: str, unit_required: bool
) -> dict[str, np.ndarray]:
    """The SI columns (``t`` excluded) of one mapped stream (spec §5.3).

    ``read(source)`` returns a channel's raw values and its unit as the source states it (None when the
    source states none; raises E503 for an unknown channel).
    """
    pointer = f"/streams/{kind}/columns"
    allowed = [c for c, _ in expected_columns(kind, present=list(smap.columns))][1:]
    unknown = [c for c in smap.columns if c not in allowed]
    if unknown:
        raise fail(
            Code.IMPORT_MAP_INVALID,
            f"{kind} has no column {unknown[0]!r}",
            file=label,
            pointer=f"{pointer}/{unknown[0]}",
            expected=allowed,
            found=unknown[0],
        )
    missing = [c for c in allowed if c not in smap.columns]
    if missing:
        raise fail(
            Code.IMPORT_MAP_INVALID,
            f"the {kind} map lacks columns {missing}",
            file=label,
            pointer=pointer,
            expected=allowed,
            found=list(smap.columns),
        )
    units = dict(expected_columns(kind, present=list(smap.columns)))
    nan_allowed = kind_table(kind)["nan_allowed"]
    out: dict[str, np.ndarray] = {}
    for col in allowed:
        ch = as_channel(smap.columns[col])
        where = {"file": label, "pointer": f"{pointer}/{col}", "column": col}
        if ch.value is not None:
            raw, stated = np.full(n, ch.value, dtype=np.float64), None
        else:
            assert ch.source is not None  # ChannelMap._one_origin: exactly one of source and value
            raw, stated = read(ch.source)
        unit = ch.unit if ch.unit is not None else stated
        if unit is None and (unit_required or ch.value is not None):
            raise fail(
                Code.IMPORT_MAP_INVALID,
                f"column {col!r} of {kind} needs a 'unit' (this source states none)",
                expected="a unit of spec §5.3",
                found=None,
                **where,
            )
        values = raw if (ch.scale == 1.0 and ch.offset == 0.0) else raw * ch.scale + ch.offset
        target = units[col]
        if ch.threshold is not None:
            if target != "1":
                raise fail(
                    Code.IMPORT_MAP_INVALID,
                    f"'threshold' applies only to dimensionless columns; {col!r} is in {target}",
                    expected="1",
                    found=target,
                    **where,
                )
            if (unit or "").strip() not in UNITS:
                raise fail(
                    Code.IMPORT_UNIT_UNKNOWN,
                    f"unit {unit!r} is not in the conversion table (spec §5.3)",
                    expected=sorted(UNITS),
                    found=unit,
                    **where,
                )
            values = np.where(values >= ch.threshold, 1.0, 0.0)
        else:
            values = unit_conversion(unit, target, **where).to_si(values)
        if not nan_allowed:
            bad = ~np.isfinite(values)
            if bad.any():
                i = int(np.argmax(bad))
                code = Code.NAN_NOT_ALLOWED if np.isnan(values[i]) else Code.NON_FINITE_VALUE
                raise fail(
                    code,
                    f"{kind} column {col!r} (from {ch.source!r}) holds a non-finite value at sample {i}",
                    file=source_file,
                    column=ch.source,
                    expected="finite values",
                    found=str(values[i]),
                )
        outside = values_outside_set(kind, col, values)
        if outside is not None and outside[0].any():
            other, words = outside
            i = int(np.argmax(other))
            raise fail(
                Code.VALUE_NOT_ALLOWED,
                f"{kind} column {col!r} (from {ch.source!r}) holds {int(other.sum())} values other than "
                f"{words}, first at sample {i}; map it with a 'threshold'",
                file=source_file,
                column=ch.source,
                expected=list(ALLOWED_VALUES[(kind, col)]),
                found=float(values[i]),
            )
        out[col] = values
    return out


VECTOR_TRIPLETS = {"commanded_wrench": (("fx", "fy", "fz"), ("tx", "ty", "tz"))}


def rotate_into_world(kind: str, columns: dict[str, np.ndarray], placement: Pose, *, label: str) -> dict[str, np.ndarray]:
    """Express a stream logged in the device frame D in W (spec §5.2 ``from_frame``): every vector
    triplet of the kind is rotated by the quaternion of ``device_placement`` (D → W). A wrench's
    reference point does not move, so its torque rotates like its force."""
    if kind not in VECTOR_TRIPLETS:
        raise fail(
            Code.IMPORT_MAP_INVALID,
            f"from_frame applies to {sorted(VECTOR_TRIPLETS)}, not {kind}",
            file=label,
            pointer=f"/streams/{kind}/from_frame",
            expected=sorted(VECTOR_TRIPLETS),
            found=kind,
        )
    rotation = quat_to_matrix(np.asarray(placement.quaternion, dtype=np.float64))
    out = dict(columns)
    for triplet in VECTOR_TRIPLETS[kind]:
        v = np.stack([columns[c] for c in triplet], axis=1) @ rotation.T
        out.update({c: v[:, i] for i, c in enumerate(triplet)})
    return out


def mapped_streams(
    m: ImportMap, n: int, read: SourceReader, *, label: str, source_file: str, unit_required: bool
) -> dict[str, dict[str, np.ndarray]]:
    """Every mapped stream's SI columns (``t`` excluded), rotated into W where ``from_frame`` asks."""
    out = {}
    for kind, smap in m.streams.items():
        cols = build_stream_columns(kind, smap, n, read, label=label, source_file=source_file, unit_required=unit_required)
        if smap.from_frame == "device":
            cols = rotate_into_world(kind, cols, m.session.device_placement, label=label)
        out[kind] = cols
    return out


def check_trial_streams(m: ImportMap, kinds: list[str], label: str) -> None:
    """The protocol's required streams and an active protocol's rendering (spec §2.5), checked before writing."""
    proto = schemas.load("protocols.json")["protocols"][m.trial.protocol]
    missing = [k for k in proto["required"] if k not in kinds]
    if missing:
        raise fail(
            Code.IMPORT_MAP_INVALID,
            f"protocol {m.trial.protocol!r} requires streams {missing} the map does not produce",
            file=label,
            pointer="/streams",
            expected=proto["required"],
            found=sorted(kinds),
        )
    if proto["passive"] is False and m.trial.rendering is None:
        raise fail(
            Code.IMPORT_MAP_INVALID,
            f"protocol {m.trial.protocol!r} is active: the trial needs 'rendering'",
            file=label,
            pointer="/trial/rendering",
            expected="rendering parameters",
            found=None,
        )
