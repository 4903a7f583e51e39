"""Which module computes each metric family (spec §15.4).

The families are the definition files ``schemas/<v>/metrics/<family>.json``; the module that computes a
family is the entry point of the family's id in the group :data:`FAMILY_ENTRY_POINTS` (declared in
pyproject.toml), so the standard's data names no code. That module exposes
``compute(ctx: ComputeContext) -> list[MetricResult | Unavailable]``.
"""

from __future__ import annotations

from functools import lru_cache
from importlib.metadata import entry_points

from haptify.metrics.metric_definitions import all_families

#: The entry-point group naming, by family id, the module that computes each metric family (spec §15.4).
FAMILY_ENTRY_POINTS = "haptify.metric_families"


@lru_cache(maxsize=1)
def family_modules() -> list[tuple[str, str]]:
    """``(family, module)`` for every defined family that has a computing module, in definition order
    (spec §15.4); families computed by nobody (e.g. calibration records) have no entry point."""
    modules = {ep.name: ep.value for ep in entry_points(group=FAMILY_ENTRY_POINTS)}
    return [(f.family, modules[f.family]) for f in all_families() if f.family in modules]


def family_module(metric_id: str) -> str:
    """The module computing ``metric_id`` (spec §15.4)."""
    family = next(f.family for f in all_families() for m in f.metrics if m.id == metric_id)
    return dict(family_modules())[family]
