"""The force-plate calibration trials of the virtual examiner (paper Appendix 1–2): a ball dropped on the
plate (impact trial) and a weight set down on a grid of 30 positions (COP trial), as loads on the plate
(:class:`PlateLoad`) with the markers of the carried weight."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from haptify.formats.conventions import (
    STANDARD_GRAVITY,
)
from haptify_tools.twin.hand_path import clock, minimum_jerk


@dataclass
class PlateLoad:
    """An external load on the force plate: force (N, W) applied at ``point_W`` (m) on the plate, per sample.
    The ball and the weight of paper Appendix 1–2."""

    t: np.ndarray
    force_W: np.ndarray
    point_W: np.ndarray
    rate_hz: float
    meta: dict = field(default_factory=dict)
    markers_W: dict[str, np.ndarray] = field(default_factory=dict)


def ball_impact(
    rng: np.random.Generator,
    duration_s: float = 3.0,
    *,
    rate_hz: float = 1000.0,
    mass_kg: float = 0.05,
    drop_height_m: float = 0.2,
    restitution: float = 0.5,
    contact_s: float = 0.003,
    t0: float = 0.0,
) -> PlateLoad:
    """Plate impact trial (paper Appendix 1): a ball dropped on the plate centre, bouncing a few times.

    Each contact is a half-sine force pulse of length ``contact_s`` carrying the impulse
    ``m (1 + e) v``; the pulse is integrated over each sample (no aliasing of the short pulse); a
    ±15 % horizontal component excites the plate's horizontal modes as well.
    """
    t = clock(duration_s, rate_hz, t0)
    rel = t - t0
    v = math.sqrt(2 * STANDARD_GRAVITY * drop_height_m)
    impacts = []
    now = 0.5
    while v > 0.05 and now < rel[-1] - 0.1:
        impacts.append((now, mass_kg * (1 + restitution) * v))
        v *= restitution
        now += 2 * v / STANDARD_GRAVITY
    horiz = rng.uniform(-0.15, 0.15, 2)
    dt = 1.0 / rate_hz
    fz = np.zeros_like(rel)
    for start, impulse in impacts:
        peak = impulse * math.pi / (2 * contact_s)
        # exact integral of the half-sine over each sample interval [t_k, t_k + dt]
        a = np.clip(rel - start, 0, contact_s)
        b = np.clip(rel + dt - start, 0, contact_s)
        fz += peak * contact_s / math.pi * (np.cos(np.pi * a / contact_s) - np.cos(np.pi * b / contact_s)) / dt
    force = np.stack([horiz[0] * fz, horiz[1] * fz, -fz], axis=1)
    point = np.zeros((len(rel), 3))
    meta = {
        "mass_kg": mass_kg,
        "drop_height_m": drop_height_m,
        "restitution": restitution,
        "contact_s": contact_s,
        "impacts": [{"t": t0 + s, "impulse_N_s": j} for s, j in impacts],
        "horizontal_ratio": horiz.tolist(),
    }
    return PlateLoad(t=t, force_W=force, point_W=point, rate_hz=rate_hz, meta=meta)


def cop_grid(nx: int = 6, ny: int = 5, half_extent_m: tuple[float, float] = (0.2, 0.16)) -> np.ndarray:
    """The 30 equally spaced weight positions (x, y) in m of the COP trial (paper Appendix 2)."""
    xs = np.linspace(-half_extent_m[0], half_extent_m[0], nx)
    ys = np.linspace(-half_extent_m[1], half_extent_m[1], ny)
    return np.array([(x, y) for y in ys for x in xs])


COP_MARKERS = ("cop_w1", "cop_w2", "cop_w3")
COP_DWELL_S = 1.0  # s the weight rests at each position
COP_MOVE_S = 0.6  # s to carry it to the next position
COP_MARKER_OFFSETS = np.array([[0.02, 0.0, 0.06], [-0.01, 0.017, 0.06], [-0.01, -0.017, 0.06]])  # on the weight's top


def weight_placements(
    rng: np.random.Generator,
    *,
    rate_hz: float = 1000.0,
    mass_kg: float = 2.0,
    dwell_s: float = COP_DWELL_S,
    move_s: float = COP_MOVE_S,
    positions: np.ndarray | None = None,
    position_jitter_m: float = 0.003,
    t0: float = 0.0,
) -> PlateLoad:
    """COP trial (paper Appendix 2): a weight set down at 30 equally spaced positions in turn.

    While set down the weight loads the plate with ``m·g`` at its position (placement ramps of 0.1 s);
    between positions it is carried through the air (no load). Three markers on its top give its
    position (``markers_W``, sampled on the same clock; the rig samples them at the mocap rate).
    """
    pos = cop_grid() if positions is None else np.asarray(positions, float)
    pos = pos + rng.uniform(-position_jitter_m, position_jitter_m, pos.shape)
    n = len(pos)
    duration = 0.5 + n * (dwell_s + move_s) + 0.5
    t = clock(duration, rate_hz, t0)
    rel = t - t0
    load = np.zeros_like(rel)
    centre = np.zeros((len(rel), 3))
    start_xy = np.array([0.35, 0.0])  # beside the plate before the first placement
    prev = start_xy
    now = 0.5
    ramp = 0.1
    for xy in pos:
        m = (rel >= now) & (rel < now + move_s)
        s = minimum_jerk((rel[m] - now) / move_s)
        centre[m, :2] = prev + (xy - prev)[None, :] * s[:, None]
        centre[m, 2] = 0.05 * np.sin(np.pi * s)
        m2 = (rel >= now + move_s) & (rel < now + move_s + dwell_s)
        centre[m2, :2] = xy
        local = rel[m2] - (now + move_s)
        load[m2] = minimum_jerk(np.minimum(local / ramp, (dwell_s - local) / ramp).clip(0.0, 1.0))
        prev = xy
        now += move_s + dwell_s
    rest = rel >= now
    centre[rest, :2] = prev
    before = rel < 0.5
    centre[before, :2] = start_xy
    force = np.zeros((len(rel), 3))
    force[:, 2] = -mass_kg * STANDARD_GRAVITY * load
    point = centre.copy()
    point[:, 2] = 0.0
    markers = {name: centre + off[None, :] for name, off in zip(COP_MARKERS, COP_MARKER_OFFSETS)}
    meta = {
        "mass_kg": mass_kg,
        "positions_m": pos.tolist(),
        "dwell_s": dwell_s,
        "move_s": move_s,
        "marker_offsets_m": COP_MARKER_OFFSETS.tolist(),
    }
    return PlateLoad(t=t, force_W=force, point_W=point, rate_hz=rate_hz, meta=meta, markers_W=markers)
