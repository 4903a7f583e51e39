"""Source units and their conversion to SI (spec §5.3), from ``schemas/<v>/import-units.json``."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from haptify import schemas
from haptify.codes import Code
from haptify.errors import fail


@dataclass(frozen=True)
class Unit:
    """A source unit: its dimension and the conversion ``si = (value · mul) / div`` (spec §5.3)."""

    dimension: str
    mul: float = 1.0
    div: float = 1.0

    def to_si(self, values: np.ndarray) -> np.ndarray:
        """Convert ``values`` to SI: one multiplication, then one division, each skipped when it is by 1."""
        out = np.asarray(values, dtype=np.float64)
        if self.mul != 1.0:
            out = out * self.mul
        if self.div != 1.0:
            out = out / self.div
        return out


def _unit_table() -> tuple[dict[str, Unit], dict[str, str]]:
    table = schemas.load("import-units.json")
    units = {
        name: Unit(row["dimension"], float(row["mul"]), float(row["div"])) for row in table["units"] for name in row["spellings"]
    }
    return units, dict(table["si_units"])


# Every accepted spelling of a source unit, and the dimension of each SI column unit (spec §1.1, §5.3),
# from schemas/<v>/import-units.json. Decimal sub-units divide by an integer power of ten, so a value
# converts to the correctly rounded SI double (mm → m is x / 1000, not x · 0.001).
UNITS, SI_DIMENSION = _unit_table()


def unit_conversion(unit: str | None, target: str, **where: Any) -> Unit:
    """The conversion from source ``unit`` to the SI ``target`` unit of a column (spec §5.3).

    E504 when ``unit`` is not in the table or has another dimension than ``target``; ``where`` names
    the file and column for the error.
    """
    dim = SI_DIMENSION[target]
    spelled = (unit or "").strip()
    known = UNITS.get(spelled)
    accepted = sorted(n for n, u in UNITS.items() if u.dimension == dim)
    if known is None:
        raise fail(
            Code.IMPORT_UNIT_UNKNOWN,
            f"unit {spelled!r} is not in the conversion table (spec §5.3)",
            expected=accepted,
            found=spelled,
            **where,
        )
    if known.dimension != dim:
        raise fail(
            Code.IMPORT_UNIT_UNKNOWN,
            f"unit {spelled!r} is a {known.dimension}, the column needs a {dim} ({target})",
            expected=accepted,
            found=spelled,
            **where,
        )
    return known
