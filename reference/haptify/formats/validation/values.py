"""The value columns of a stream (spec §2.7, §4.4): infinities (E210), the NaN policy and occlusion
(E204, W405), closed value sets (E214), quaternion norms (E207) and sensor ranges (W401) — checked chunk by
chunk, keeping counts, first/last times and extremes only."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np

from haptify import schemas
from haptify.codes import Code
from haptify.errors import Finding
from haptify.formats.conventions import QUATERNION_NORM_TOLERANCE
from haptify.formats.session_format import ALLOWED_VALUES, SensorRange, Stream, kind_table, quaternion_groups, values_outside_set

# --- thresholds of spec §2.7 and §4.4 -------------------------------------------------------------
OCCLUSION_WARNING_SHARE = 0.20  # share of occluded samples above which W405 is raised

MOCAP_KINDS = frozenset(k for k, v in schemas.load("stream-kinds.json")["kinds"].items() if v.get("nan_allowed"))


@dataclass
class _Tally:
    """The samples a mask selects, over consecutive chunks of a stream: how many, and the first and last
    finite time among them (a finding's ``time_range``)."""

    count: int = 0
    first: float | None = None
    last: float | None = None

    def add(self, t: np.ndarray, mask: np.ndarray) -> None:
        idx = np.flatnonzero(mask)
        if idx.size == 0:
            return
        self.count += int(idx.size)
        times = t[idx]
        times = times[np.isfinite(times)]
        if times.size:
            if self.first is None:
                self.first = float(times[0])
            self.last = float(times[-1])

    @property
    def span(self) -> tuple[float, float] | None:
        return None if self.first is None or self.last is None else (self.first, self.last)


class ValueScan:
    """The value columns of a stream, chunk by chunk (spec §2.7, §4.4): infinities (E210), the NaN policy
    (E204, occlusion W405), closed value sets (E214), quaternion norms (E207) and sensor ranges (W401).
    Each check keeps counts, first/last times and extremes only, so the findings are those of the whole
    table whatever the chunking — and memory holds one chunk."""

    def __init__(self, s: Stream, cols: list[str], rng: SensorRange | None) -> None:
        self.stream, self.cols = s, cols
        self.inf = [_Tally() for _ in cols]
        self.nan = [_Tally() for _ in cols]
        spec = kind_table(s.kind)
        self.mocap = s.kind in MOCAP_KINDS
        if "entity_columns" in spec:
            width = len(spec["entity_columns"])
            groups = [(ent, list(range(k * width, (k + 1) * width))) for k, ent in enumerate(s.entities or [])]
        else:
            groups = [(s.kind, list(range(len(cols))))]
        self.groups = [
            (name, idx, _Tally(), _Tally()) for name, idx in groups if idx and idx[-1] < len(cols)
        ]  # partial, occluded
        self.sets: list[tuple[int, _Tally, list[np.ndarray]]] = [
            (k, _Tally(), []) for k, c in enumerate(cols) if values_outside_set(s.kind, c, np.empty(0)) is not None
        ]
        index = {c: k for k, c in enumerate(cols)}
        self.quats: list[tuple[list[str], list[int], _Tally, list[float | None]]] = [
            (list(g), [index[c] for c in g], _Tally(), [None])
            for g in quaternion_groups(s.kind, s.entities)
            if all(c in index for c in g)
        ]
        limits = [(k, _range_limit(c, rng)) for k, c in enumerate(cols)] if rng is not None else []
        self.ranges = [(k, limit, _Tally(), [0.0]) for k, limit in limits if limit is not None]

    def feed(self, t: np.ndarray, values: np.ndarray) -> None:
        if not np.isfinite(values).all():  # the column-by-column account only when something is not finite
            nan, inf = np.isnan(values), np.isinf(values)
            for col in np.flatnonzero(inf.any(axis=0)):
                self.inf[col].add(t, inf[:, col])
            for col in np.flatnonzero(nan.any(axis=0)):
                self.nan[col].add(t, nan[:, col])
            for _, idx, partial, occluded in self.groups:
                g = nan[:, idx]
                some, every = g.any(axis=1), g.all(axis=1)
                partial.add(t, some & ~every)
                occluded.add(t, every)
        for k, tally, seen in self.sets:
            outside = values_outside_set(self.stream.kind, self.cols[k], values[:, k])
            assert outside is not None  # self.sets holds the columns with a closed value set only
            other, _ = outside
            if other.any():
                tally.add(t, other)
                seen[:] = [np.union1d(seen[0], values[other, k]) if seen else np.unique(values[other, k])]
        for _, idx, tally, worst in self.quats:
            q = values[:, idx]
            norm = np.sqrt(np.einsum("ij,ij->i", q, q))
            off = np.isfinite(q).all(axis=1) & (np.abs(norm - 1.0) > QUATERNION_NORM_TOLERANCE)
            if off.any():
                tally.add(t, off)
                local = float(norm[off][np.argmax(np.abs(norm[off] - 1.0))])
                if worst[0] is None or abs(local - 1.0) > abs(worst[0] - 1.0):  # ties keep the first, as argmax
                    worst[0] = local
        for k, limit, tally, peak in self.ranges:
            with np.errstate(invalid="ignore"):
                over = np.isfinite(values[:, k]) & (np.abs(values[:, k]) > limit)
            if over.any():
                tally.add(t, over)
                peak[0] = max(peak[0], float(np.max(np.abs(values[over, k]))))

    def findings(self, rows: int, add: Callable[[Finding], None]) -> None:
        """Add the value findings in the order of spec §4.4: E210, E204/W405, E214, E207, W401."""
        s, cols, label = self.stream, self.cols, self.stream.file
        for k, tally in enumerate(self.inf):
            if tally.count:
                add(
                    Finding(
                        Code.NON_FINITE_VALUE,
                        f"column {cols[k]!r} holds {tally.count} infinite values",
                        file=label,
                        column=cols[k],
                        time_range=tally.span,
                        expected="finite values",
                        found="inf",
                    )
                )
        if self.mocap:  # mocap NaN policy (spec §2.7): whole entities NaN together; warn above the occlusion share
            for name, idx, partial, occluded in self.groups:
                if partial.count:
                    add(
                        Finding(
                            Code.NAN_NOT_ALLOWED,
                            f"{name}: {partial.count} samples have some but not all of {[cols[i] for i in idx]} NaN",
                            file=label,
                            column=cols[idx[0]],
                            time_range=partial.span,
                            expected="all columns of an occluded entity NaN together",
                            found="partial NaN",
                        )
                    )
                share = occluded.count / rows
                if share > OCCLUSION_WARNING_SHARE:
                    add(
                        Finding(
                            Code.OCCLUSION_HIGH,
                            f"{name} is occluded in {share:.0%} of the samples",
                            file=label,
                            column=cols[idx[0]],
                            time_range=occluded.span,
                            expected=f"at most {OCCLUSION_WARNING_SHARE:.0%}",
                            found=round(share, 4),
                        )
                    )
        else:
            for k, tally in enumerate(self.nan):
                if tally.count:
                    add(
                        Finding(
                            Code.NAN_NOT_ALLOWED,
                            f"column {cols[k]!r} holds {tally.count} NaN values; {s.kind} allows none",
                            file=label,
                            column=cols[k],
                            time_range=tally.span,
                            expected="no NaN",
                            found="NaN",
                        )
                    )
        for k, tally, seen in self.sets:
            if tally.count:
                col = cols[k]
                outside = values_outside_set(s.kind, col, np.empty(0))
                assert outside is not None  # self.sets holds the columns with a closed value set only
                add(
                    Finding(
                        Code.VALUE_NOT_ALLOWED,
                        f"column {col!r} holds {tally.count} values other than {outside[1]} "
                        f"({seen[0].size} distinct, e.g. {float(seen[0][0])!r})",
                        file=label,
                        column=col,
                        time_range=tally.span,
                        expected=list(ALLOWED_VALUES[(s.kind, col)]),
                        found=[float(v) for v in seen[0][:5]],
                    )
                )
        for group, _, tally, worst in self.quats:
            if tally.count:
                add(
                    Finding(
                        Code.QUATERNION_NOT_UNIT,
                        f"{tally.count} quaternions ({', '.join(group)}) are not unit; worst norm {worst[0]:.6g}",
                        file=label,
                        column=group[0],
                        time_range=tally.span,
                        expected=f"norm 1 ± {QUATERNION_NORM_TOLERANCE}",
                        found=worst[0],
                    )
                )
        for k, limit, tally, peak in self.ranges:
            if tally.count:
                add(
                    Finding(
                        Code.SENSOR_RANGE_EXCEEDED,
                        f"column {cols[k]!r} exceeds the declared ±{limit:g} range at {tally.count} samples (peak {peak[0]:.6g})",
                        file=label,
                        column=cols[k],
                        time_range=tally.span,
                        expected=f"|value| ≤ {limit:g}",
                        found=peak[0],
                    )
                )


def _range_limit(column: str, rng: SensorRange) -> float | None:
    """The symmetric range (stream units) of a wrench/accel column, from the rig's SensorRange (spec §2.4)."""
    base = column.split("_")[-1]
    axis = "xyz".find(base[-1:]) if len(base) == 2 else -1
    if axis < 0:
        return None
    table = {"f": rng.force_N, "t": rng.torque_Nm, "a": rng.accel_m_per_s2}.get(base[0])
    return None if table is None else float(table[axis])
