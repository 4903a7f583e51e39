"""The rules on one trial of session.json (spec §4.3.3): one stream per kind (E306), the protocol's
required and recommended streams (E302, W404), the rendering of an active protocol (E303) and its unit
surface normal (E307), the label of protocol ``other`` (E304) and the powered flag (W403)."""

from __future__ import annotations

import math
from typing import Callable

from haptify import schemas
from haptify.codes import Code
from haptify.errors import Finding
from haptify.formats.conventions import QUATERNION_NORM_TOLERANCE
from haptify.formats.session_format import Trial
from haptify.formats.storage import MANIFEST

# --- tolerance of spec §2.5 ----------------------------------------------------------------------
NORMAL_NORM_TOLERANCE = QUATERNION_NORM_TOLERANCE  # |‖n‖ − 1| allowed in a rendering's surface_normal (E307, spec §2.5)


def check_trial(index: int, trial: Trial, add: Callable[[Finding], None]) -> None:
    """Protocol requirements, rendering, label, powered flag, one stream per kind of the trial at
    ``/trials/<index>`` of session.json (spec §4.3.3); each finding is handed to ``add``."""
    where = f"/trials/{index}"
    proto = schemas.load("protocols.json")["protocols"][trial.protocol]
    kinds = [s.kind for s in trial.streams]
    for j, kind in enumerate(kinds):
        if kind in kinds[:j]:
            add(
                Finding(
                    Code.DUPLICATE_STREAM_KIND,
                    f"trial {trial.id!r} has two {kind} streams",
                    file=MANIFEST,
                    pointer=f"{where}/streams/{j}/kind",
                    expected=f"one {kind} stream",
                    found=kinds.count(kind),
                )
            )
    for kind in proto["required"]:
        if kind not in kinds:
            add(
                Finding(
                    Code.REQUIRED_STREAM_MISSING,
                    f"{trial.protocol} trial {trial.id!r} has no {kind} stream",
                    file=MANIFEST,
                    pointer=f"{where}/streams",
                    expected=proto["required"],
                    found=kinds,
                )
            )
    for kind in proto["recommended"]:
        if kind not in kinds:
            add(
                Finding(
                    Code.RECOMMENDED_STREAM_MISSING,
                    f"{trial.protocol} trial {trial.id!r} has no {kind} stream",
                    file=MANIFEST,
                    pointer=f"{where}/streams",
                    expected=proto["recommended"],
                    found=kinds,
                )
            )
    passive = proto["passive"]
    if passive is False and trial.rendering is None:
        add(
            Finding(
                Code.RENDERING_MISSING,
                f"active {trial.protocol} trial {trial.id!r} has no rendering parameters",
                file=MANIFEST,
                pointer=f"{where}/rendering",
                expected="a rendering object",
                found=None,
            )
        )
    if trial.rendering is not None:
        n = trial.rendering.surface_normal
        try:
            norm = math.hypot(*n)  # hypot: no overflow for components near 1e308
        except OverflowError:
            norm = math.inf
        if not abs(norm - 1.0) <= NORMAL_NORM_TOLERANCE:
            add(
                Finding(
                    Code.SURFACE_NORMAL_NOT_UNIT,
                    f"trial {trial.id!r}: the rendering's surface_normal has norm {norm:.6g}",
                    file=MANIFEST,
                    pointer=f"{where}/rendering/surface_normal",
                    expected=f"norm 1 ± {NORMAL_NORM_TOLERANCE}",
                    found=list(n),
                )
            )
    if trial.protocol == "other" and not (trial.label or "").strip():
        add(
            Finding(
                Code.LABEL_MISSING,
                f"trial {trial.id!r} of protocol 'other' has no label",
                file=MANIFEST,
                pointer=f"{where}/label",
                expected="a label such as 'figure_eight'",
                found=trial.label,
            )
        )
    if passive is not None and trial.powered == passive:
        add(
            Finding(
                Code.POWERED_FLAG_UNUSUAL,
                f"{'passive' if passive else 'active'} protocol {trial.protocol!r} recorded with powered={str(trial.powered).lower()}",
                file=MANIFEST,
                pointer=f"{where}/powered",
                expected=not passive,
                found=trial.powered,
            )
        )
