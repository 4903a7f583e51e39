"""The time column of a stream (spec §4.4): finite and strictly increasing (E203), its mean rate within
:data:`RATE_TOLERANCE` of the declared one (E206), its intervals regular (W402) — checked chunk by chunk."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Callable

import numpy as np

from haptify.codes import Code
from haptify.errors import Finding

# --- tolerances of spec §4.4 ---------------------------------------------------------------------
RATE_TOLERANCE = 0.01  # |actual mean rate / rate_hz − 1| allowed (E206)
INTERVAL_LOW, INTERVAL_HIGH = 0.5, 1.5  # an interval outside [0.5, 1.5] / rate_hz is irregular (W402)


@dataclass
class TimeScan:
    """The time column of a stream, chunk by chunk (spec §4.4: finite, strictly increasing, mean rate,
    regular intervals). The interval across a chunk border is judged with the previous chunk's last time,
    so the findings are those of the whole column."""

    rate_hz: float
    rows: int = 0
    first: float = math.nan  # t of the first and of the last sample
    last: float = math.nan
    non_finite: int = 0
    last_finite: float | None = None
    gap: list[float | None] | None = None  # finite times before and after the first non-finite one
    gap_open: bool = False  # no finite time seen yet after the first non-finite one
    reversals: int = 0
    first_reversal: tuple[int, float, float] | None = None  # row k, t[k], t[k+1]
    odd: int = 0  # intervals outside [INTERVAL_LOW, INTERVAL_HIGH] / rate_hz
    odd_span: list[float] = field(default_factory=list)  # start of the first, end of the last
    dt_max: float = -math.inf
    dt_min: float = math.inf

    def feed(self, t: np.ndarray) -> None:
        tt = t if self.rows == 0 else np.concatenate(([self.last], t))
        base = self.rows - (tt.size - t.size)  # row of tt[0]
        if self.rows == 0 and t.size:
            self.first = float(t[0])
        finite = np.isfinite(t)
        if self.gap_open and finite.any():
            assert self.gap is not None  # the gap is open only once it was found
            self.gap[1], self.gap_open = float(t[finite][0]), False
        if not finite.all():
            bad = np.flatnonzero(~finite)
            self.non_finite += int(bad.size)
            if self.gap is None:
                k = int(bad[0])
                before, after = t[:k][finite[:k]], t[k + 1 :][finite[k + 1 :]]
                self.gap = [float(before[-1]) if before.size else self.last_finite, float(after[0]) if after.size else None]
                self.gap_open = not after.size
        if finite.any():
            self.last_finite = float(t[finite][-1])
        if t.size:
            self.rows += int(t.size)
            self.last = float(t[-1])
        dt = np.diff(tt)
        bad_dt = ~(dt > 0) & np.isfinite(dt)
        if bad_dt.any():
            j = int(np.flatnonzero(bad_dt)[0])
            self.reversals += int(bad_dt.sum())
            if self.first_reversal is None:
                self.first_reversal = (base + j, float(tt[j]), float(tt[j + 1]))
        nominal = 1.0 / self.rate_hz
        odd = np.flatnonzero((dt < INTERVAL_LOW * nominal) | (dt > INTERVAL_HIGH * nominal))
        if odd.size:
            self.odd += int(odd.size)
            self.odd_span = [self.odd_span[0] if self.odd_span else float(tt[odd[0]]), float(tt[odd[-1] + 1])]
        if dt.size:
            self.dt_max, self.dt_min = max(self.dt_max, float(dt.max())), min(self.dt_min, float(dt.min()))

    def findings(self, label: str, add: Callable[[Finding], None]) -> bool:
        """Add the time findings (E203, E206, W402); True when the time column is sound (finite, increasing)."""
        if self.non_finite:
            add(
                Finding(
                    Code.TIME_NOT_INCREASING,
                    f"time column holds {self.non_finite} non-finite values",
                    file=label,
                    column="t",
                    time_range=self._gap_span(),
                    expected="finite seconds",
                    found="NaN or infinity",
                )
            )
        if self.first_reversal is not None:  # noted with the first of the reversals
            k, a, b = self.first_reversal
            add(
                Finding(
                    Code.TIME_NOT_INCREASING,
                    f"time does not strictly increase at {self.reversals} intervals (first at row {k + 1})",
                    file=label,
                    column="t",
                    time_range=(min(a, b), max(a, b)),
                    expected="t[i+1] > t[i]",
                    found=f"t[{k}]={a!r}, t[{k + 1}]={b!r}",
                )
            )
        if self.non_finite or self.reversals:
            return False
        actual = (self.rows - 1) / (self.last - self.first)
        if abs(actual / self.rate_hz - 1.0) > RATE_TOLERANCE:
            add(
                Finding(
                    Code.RATE_MISMATCH,
                    f"actual mean rate {actual:.6g} Hz differs from the declared {self.rate_hz:g} Hz by more than "
                    f"{RATE_TOLERANCE:.0%}",
                    file=label,
                    column="t",
                    time_range=(self.first, self.last),
                    expected=self.rate_hz,
                    found=round(actual, 6),
                )
            )
        if self.odd:
            nominal = 1.0 / self.rate_hz
            add(
                Finding(
                    Code.SAMPLE_INTERVAL_IRREGULAR,
                    f"{self.odd} sample intervals lie outside [{INTERVAL_LOW}, {INTERVAL_HIGH}] × {nominal:.6g} s "
                    f"(largest {self.dt_max:.6g} s, smallest {self.dt_min:.6g} s)",
                    file=label,
                    column="t",
                    time_range=(self.odd_span[0], self.odd_span[1]),
                    expected=nominal,
                    found=self.odd,
                )
            )
        return True

    def _gap_span(self) -> tuple[float, float] | None:
        """The finite times around the first non-finite one (either alone when the other does not exist)."""
        before, after = self.gap if self.gap is not None else (None, None)
        if before is None:
            return None if after is None else (after, after)
        return (before, after if after is not None else before)
