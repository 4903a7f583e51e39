"""The virtual examiner: seeded hand trajectories for every protocol (design §4; paper §V, §III-C, Appendix).

Every generator takes a :class:`numpy.random.Generator` and returns samples on a uniform clock
(default 2 kHz, the fastest sensor of the rig, so the accelerometer model can differentiate the path
without interpolation). Positions are of the gimbal centre in the world frame W (m), orientations are
unit quaternions ``[w, x, y, z]`` rotating the handle body frame H to W (spec §1.3).

Where a generator needs the device's reach it asks a :class:`~haptify_tools.twin.reach.Reach`: joint-limit box in unit
coordinates (``s ∈ [0, 1]³`` mapped through the coupled limits, reference ``configurations_from_unit``),
forward kinematics into W, inverse kinematics and the base-collision clearance of the twin (its TRUE
kinematics: the examiner moves the real device, link-length errors and all).

Protocol limits (paper §V): free-space wandering below 0.16 m/s and 16 °/s (averages ≈ 0.05 m/s and
≈ 4 °/s, §VI-B); local dynamic oscillations from 0.5 to 4 Hz in x, y, z and the diagonals for about
140 s from the workspace centre (§V-C); circles on the rendered surface while pressing lightly (§V-D);
repeated presses until the workspace edge (§V-E); physiological tremor 8–12 Hz on every hand-held path.

The path primitives (clock, noise, tremor, :class:`~haptify_tools.twin.hand_path.HandTrajectory`) are in
:mod:`haptify_tools.twin.hand_path`, the force-plate trials (ball impact, COP weights) in
:mod:`haptify_tools.twin.plate_loads`.
"""

from __future__ import annotations

import math

import numpy as np

from haptify.formats.conventions import (
    quat_from_axis_angle,
    quat_multiply,
    quat_normalize,
)
from haptify_tools.twin.hand_path import (
    DEFAULT_RATE_HZ,
    DEG,
    NATURAL_GRIP,
    HandTrajectory,
    _finish,
    clock,
    derivative,
    minimum_jerk,
    natural_orientation,
    smooth_noise,
)
from haptify_tools.twin.reach import Reach
from haptify_tools.twin.reach import reach_from_twin as reach_from_twin  # re-exported: benchmarks/bench_twin_physics.py

# Protocol limits and targets, paper §V-B/§VI-B (free space), §V-C (local dynamic).
FREE_SPACE_MAX_SPEED = 0.16  # m/s, paper §V-B
FREE_SPACE_MAX_ANGULAR = 16 * DEG  # rad/s, paper §V-B
FREE_SPACE_MEAN_SPEED = 0.05  # m/s, paper §VI-B
FREE_SPACE_MEAN_ANGULAR = 4 * DEG  # rad/s, paper §VI-B
FIGURE_EIGHT_PERIODS_S = (4.0, 1.2)  # s, the first and the last loop of the figure eight
SURFACE_PERIODS_S = (4.0, 1.0)  # s, the first and the last circle on the frictionless surface
PRESS_SPEED = 0.04  # m/s, the stiffness presses' descent
OSCILLATION_BAND_HZ = (0.5, 4.0)  # paper §V-C
LOCAL_DYNAMIC_DURATION = 140.0  # s, paper §V-C


# --- protocol generators -------------------------------------------------------------------------


def boundary_sweep(
    rng: np.random.Generator,
    reach: Reach,
    duration_s: float = 75.0,
    *,
    rate_hz: float = DEFAULT_RATE_HZ,
    line_spacing_m: float = 0.03,
    min_stroke_m: float = 0.03,
    t0: float = 0.0,
) -> HandTrajectory:
    """Workspace protocol (paper §IV-A, §V-A): corners, edges and faces of the joint-limit box.

    Each of the six faces of the unit joint box is covered by a boustrophedon raster of
    lines no more than ``line_spacing_m`` apart in space (so a volume operator can close the shell; the
    first and last lines are edges, their ends corners), stroking along the face's longer direction; faces are joined
    along cube edges so the hand never leaves the boundary. Where the box boundary collides with the
    base the hand is stopped at the first contact on its way out from the centre of the box
    (:meth:`Reach.radial_stop`); where that makes the path jump, the hand lifts over the base. Each straight
    stroke is a minimum-jerk movement (the hand stops at every corner); strokes share ``duration_s``
    in proportion to their length plus ``min_stroke_m``.
    """
    waypoints, lines = _face_raster_waypoints(reach, line_spacing_m, rng)
    seg = np.linalg.norm(np.diff(waypoints, axis=0), axis=1)
    u = np.concatenate([[0.0], np.cumsum(seg)])

    def path_s(tau: np.ndarray) -> np.ndarray:
        return np.stack([np.interp(tau, u, waypoints[:, k]) for k in range(3)], axis=1)

    t = clock(duration_s, rate_hz, t0)
    rel = t - t0
    tau_grid = np.linspace(0.0, u[-1], 20000)
    pts = reach.radial_stop(path_s(tau_grid))
    tau_grid, pts = _lift_over_jumps(reach, tau_grid, pts)
    arc = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(pts, axis=0), axis=1))])
    length = float(arc[-1])
    # Every straight stroke between waypoints is a minimum-jerk movement (the hand stops at corners);
    # stroke durations are proportional to their length plus a minimum, filling the trial less 0.5 s
    # at each end.
    a_k = np.interp(u, tau_grid, arc)
    strokes = np.diff(a_k)
    keep = strokes > 1e-9
    a_start, strokes = a_k[:-1][keep], strokes[keep]
    usable = max(rel[-1] - 1.0, 1e-3)
    weight = strokes + min_stroke_m  # short strokes still take a human-like time
    ends = 0.5 + np.cumsum(weight) / weight.sum() * usable
    starts = ends - weight / weight.sum() * usable
    k = np.clip(np.searchsorted(ends, rel), 0, len(strokes) - 1)
    frac = minimum_jerk((rel - starts[k]) / (ends[k] - starts[k]))
    target = np.where(rel < 0.5, 0.0, a_start[k] + strokes[k] * frac)
    position = np.stack([np.interp(target, arc, pts[:, j]) for j in range(3)], axis=1)
    base = NATURAL_GRIP
    quat = natural_orientation(rng, t - t0, rate_hz, base_quat=base, mean_rate=6 * DEG, max_rate=30 * DEG)
    meta = {
        "path_length_m": length,
        "lines_per_face": lines,
        "line_spacing_m": line_spacing_m,
        "mean_speed_m_per_s": length / duration_s,
        "strokes": int(len(strokes)),
    }
    return _finish(rng, t, rate_hz, position, quat, "workspace", None, meta)


def _lift_over_jumps(
    reach: Reach, tau: np.ndarray, pts: np.ndarray, jump_m: float = 0.003, spacing_m: float = 0.0005
) -> tuple[np.ndarray, np.ndarray]:
    """Replace jumps in a dense path (where the blocked hand would teleport) by a lift over the obstacle.

    Between two consecutive points more than ``jump_m`` apart the hand goes straight up to a height
    where the crossing is free, across, and down, sampled every ``spacing_m``.
    """
    gaps = np.flatnonzero(np.linalg.norm(np.diff(pts, axis=0), axis=1) > jump_m)
    if not len(gaps):
        return tau, pts
    taus: list[np.ndarray] = []
    segs: list[np.ndarray] = []
    last = 0
    for i in map(int, gaps):
        a, b = pts[i], pts[i + 1]
        top = max(a[2], b[2])
        for _ in range(60):
            across = np.linspace([a[0], a[1], top], [b[0], b[1], top], 50)
            if not np.any(reach.collides(across)):
                break
            top += 0.005
        corners = np.array([a, [a[0], a[1], top], [b[0], b[1], top], b])
        legs = [
            np.linspace(corners[j], corners[j + 1], max(2, int(np.linalg.norm(corners[j + 1] - corners[j]) / spacing_m)))[1:]
            for j in range(3)
        ]
        detour = np.concatenate(legs)[:-1]
        taus += [tau[last : i + 1], np.linspace(tau[i], tau[i + 1], len(detour) + 2)[1:-1]]
        segs += [pts[last : i + 1], detour]
        last = i + 1
    taus.append(tau[last:])
    segs.append(pts[last:])
    return np.concatenate(taus), np.concatenate(segs)


def _face_raster_waypoints(reach: Reach, spacing: float, rng: np.random.Generator) -> tuple[np.ndarray, list[int]]:
    """Waypoints in the unit joint cube: a raster on each of the 6 faces, joined along cube edges.

    On each face the strokes run along the direction whose edges are longer in space, and the number of
    lines makes the largest spacing between neighbouring lines at most ``spacing`` metres.
    """
    u = np.linspace(0.0, 1.0, 41)

    def span(axis: int, side: float, along: int, other: int) -> float:
        """Largest spatial length of the face's curves running along ``along`` (``other`` held)."""
        best = 0.0
        for o in (0.0, 0.5, 1.0):
            p = np.zeros((len(u), 3))
            p[:, axis], p[:, along], p[:, other] = side, u, o
            x = reach.unit_to_W(p)
            if np.all(np.isfinite(x)):
                best = max(best, float(np.sum(np.linalg.norm(np.diff(x, axis=0), axis=1))))
        return best

    rasters, counts = [], []
    for axis in range(3):
        for side in (0.0, 1.0):
            a, b = [k for k in range(3) if k != axis]
            la, lb = span(axis, side, a, b), span(axis, side, b, a)
            i, j, across = (a, b, lb) if la >= lb else (b, a, la)  # stroke along i, step along j
            lines = max(2, int(math.ceil(across / spacing)) + 1)
            counts.append(lines)
            pts = []
            for n, v in enumerate(np.linspace(0.0, 1.0, lines)):
                for w in (0.0, 1.0) if n % 2 == 0 else (1.0, 0.0):
                    p = np.zeros(3)
                    p[axis], p[i], p[j] = side, w, v
                    pts.append(p)
            rasters.append(np.array(pts))
    order = rng.permutation(len(rasters))
    out = [rasters[order[0]]]
    for k in order[1:]:
        start, goal = out[-1][-1], rasters[k][0]
        out.append(_corner_path(start, goal)[1:])
        out.append(rasters[k])
    return np.concatenate(out), counts


def _corner_path(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """A path from corner ``a`` to corner ``b`` of the unit cube along its edges (one axis at a time)."""
    pts = [a.copy()]
    cur = a.copy()
    for k in range(3):
        if cur[k] != b[k]:
            cur = cur.copy()
            cur[k] = b[k]
            pts.append(cur)
    return np.array(pts)


def free_space_wander(
    rng: np.random.Generator,
    reach: Reach | None,
    duration_s: float = 40.0,
    *,
    rate_hz: float = DEFAULT_RATE_HZ,
    mean_speed: float = FREE_SPACE_MEAN_SPEED,
    max_speed: float = 0.75 * FREE_SPACE_MAX_SPEED,
    mean_angular: float = FREE_SPACE_MEAN_ANGULAR,
    max_angular: float = 0.75 * FREE_SPACE_MAX_ANGULAR,
    margin: float = 0.15,
    t0: float = 0.0,
    protocol: str = "free_space",
    centre_W: np.ndarray | None = None,
    extent_m: float = 0.05,
    clearance_m: float = 0.01,
    components: int = 5,
) -> HandTrajectory:
    """Free-space protocol (paper §V-B): slow wandering through the workspace interior, device off.

    The path is a smooth random curve — per joint, a sum of ``components`` slow sinusoids — in the joint
    box shrunk by ``margin`` on every side (so the hand never touches the workspace boundary; the
    wander shrinks about the centre until it keeps ``clearance_m`` from the base), mapped through the
    device's forward kinematics. One common time scale sets the mean speed to ``mean_speed`` unless
    the peak would exceed ``max_speed`` (paper: < 0.16 m/s, average ≈ 0.05 m/s); being a smooth
    function of time the path has small accelerations (no broadband content for the accelerometer).
    The hand orientation wanders naturally (< 16 °/s, average ≈ 4 °/s). With ``reach=None`` (the rig's
    baseline-vibration trial, no device) the same wander is a Cartesian path within ``extent_m`` of
    ``centre_W``.
    """
    t = clock(duration_s, rate_hz, t0)
    rel = t - t0
    freqs = rng.uniform(0.05, 0.2, (3, components))
    phases = rng.uniform(0.0, 2 * np.pi, (3, components))
    weights = rng.uniform(0.5, 1.0, (3, components))
    weights /= weights.sum(axis=1, keepdims=True)
    amp = [1.0]
    ramp = [2.0]  # s: the wander eases in from the centre and back to it at the ends

    def ease_of(tt: np.ndarray) -> np.ndarray:
        return minimum_jerk(np.minimum(1.0, np.minimum(tt, rel[-1] - tt) / ramp[0]).clip(0.0, 1.0))

    def shape(lam: float, tt: np.ndarray = rel) -> np.ndarray:
        """Wander ``(N, 3)`` at time scale ``lam``; starts and ends at the centre, peaks near ±1 per axis."""
        arg = 2 * np.pi * freqs[None, :, :] * lam * tt[:, None, None] + phases[None, :, :]
        return ease_of(tt)[:, None] * np.sum(weights[None] * (np.sin(arg) - np.sin(phases)[None]), axis=2) / norm

    norm = 1.0
    norm = np.maximum(np.max(np.abs(shape(1.0)), axis=0), 1e-6)

    if reach is not None:
        half = 0.5 - margin

        def path(lam: float, sub: int = 1) -> np.ndarray:
            return reach.unit_to_W(0.5 + amp[0] * half * shape(lam, rel[::sub]))
    else:
        c = np.asarray(centre_W if centre_W is not None else [0.0, 0.0, 0.3], dtype=float)

        def path(lam: float, sub: int = 1) -> np.ndarray:
            return c[None, :] + amp[0] * extent_m * shape(lam, rel[::sub])

    sub = max(1, int(rate_hz // 200))  # speed and clearance checks on a 200 Hz grid

    def speeds(lam: float) -> np.ndarray:
        return np.linalg.norm(derivative(path(lam, sub), rate_hz / sub), axis=1)

    def time_scale() -> tuple[float, float]:
        """The time scale whose mean speed is nearest ``mean_speed`` with the peak under ``max_speed``, from a scan of
        ×¼ … ×4, and its peak speed (m/s): speed is nearly ∝ the scale, but a faster wander can cross a part of the
        workspace where the map stretches it, so the peak jumps (none under the limit: the scale with the lowest peak)."""
        scan = [(lam, speeds(lam)) for lam in np.geomspace(0.25, 4.0, 33)]
        feasible = [(abs(np.mean(v) - mean_speed), lam, np.max(v)) for lam, v in scan if np.max(v) <= max_speed]
        if feasible:
            return min(feasible)[1:]
        return min((np.max(v), lam) for lam, v in scan)[::-1]

    for _ in range(30):
        lam, peak = time_scale()
        # the ease at the ends does not slow down with the time scale: a return to the centre that is still
        # too fast gets a longer ease (at most a fifth of the trial at each end)
        if peak > max_speed * 1.02 and ramp[0] < 0.2 * rel[-1]:
            ramp[0] = min(1.5 * ramp[0], 0.2 * rel[-1])
            continue
        # keep clear of the base: shrink the wander about the centre (the time scale changes the path)
        if reach is None or amp[0] <= 0.1 or np.min(reach.clearance(path(lam, sub))) >= clearance_m:
            break
        amp[0] *= 0.85
    position = path(lam)
    base = NATURAL_GRIP
    quat = natural_orientation(rng, rel, rate_hz, base_quat=base, mean_rate=mean_angular, max_rate=max_angular)
    meta = {
        "mean_speed_m_per_s": mean_speed,
        "max_speed_m_per_s": max_speed,
        "mean_angular_rad_per_s": mean_angular,
        "max_angular_rad_per_s": max_angular,
        "margin_unit": margin,
        "wander_scale": amp[0],
        "time_scale": lam,
    }
    return _finish(rng, t, rate_hz, position, quat, protocol, None, meta)


OSCILLATION_DIRECTIONS = {
    "x": (1, 0, 0),
    "y": (0, 1, 0),
    "z": (0, 0, 1),
    "xy": (1, 1, 0),
    "x-y": (1, -1, 0),
    "xz": (1, 0, 1),
    "x-z": (1, 0, -1),
    "yz": (0, 1, 1),
    "y-z": (0, 1, -1),
}


def local_oscillations(
    rng: np.random.Generator,
    reach: Reach,
    duration_s: float = LOCAL_DYNAMIC_DURATION,
    *,
    rate_hz: float = DEFAULT_RATE_HZ,
    band_hz: tuple[float, float] = OSCILLATION_BAND_HZ,
    max_amplitude: float = 0.06,
    max_accel: float = 38.0,
    passes: int = 2,
    t0: float = 0.0,
) -> HandTrajectory:
    """Local dynamic protocol (paper §V-C): oscillations from 0.5 to 4 Hz in x, y, z and the diagonals.

    The frequency rises geometrically from ``band_hz[0]`` to ``band_hz[1]`` over the trial (slow to as
    fast as possible); the direction cycles ``passes`` times through x, y, z and the six diagonals,
    blending smoothly between directions. The amplitude is the smaller of ``max_amplitude``, the free
    distance from the workspace centre in that direction (× 0.8), and ``max_accel / (2πf)²``; it is
    eased in and out so the path starts and ends at rest at the centre. ``max_accel`` (m/s²) and the
    fastest speed this allows (≈ 1.5 m/s at 4 Hz with 6 cm, ``max_amplitude`` in m) are the paper's
    representative distances between local-dynamic windows (§VI-D: R_a = 38 m/s², R_v = 1.6 m/s), i.e. what
    its examiner reached.
    """
    t = clock(duration_s, rate_hz, t0)
    rel = t - t0
    T = rel[-1]
    centre = reach.centre()
    f0, f1 = band_hz
    freq = f0 * (f1 / f0) ** (rel / T)
    phase = 2 * np.pi * f0 * T / math.log(f1 / f0) * ((f1 / f0) ** (rel / T) - 1.0)
    names = list(OSCILLATION_DIRECTIONS) * passes
    dirs = np.array([np.array(OSCILLATION_DIRECTIONS[n], float) / np.linalg.norm(OSCILLATION_DIRECTIONS[n]) for n in names])
    room = np.array([min(reach.free_distance(centre, d), reach.free_distance(centre, -d)) for d in dirs])
    amp_dir = np.minimum(max_amplitude, 0.8 * room)
    # Direction schedule: block k holds direction k; 15 % of each block blends to the next.
    blocks = len(names)
    x = rel / T * blocks
    k = np.minimum(x.astype(int), blocks - 1)
    frac = x - k
    blend = minimum_jerk((frac - 0.85) / 0.15)
    nxt = np.minimum(k + 1, blocks - 1)
    d = dirs[k] * (1 - blend)[:, None] + dirs[nxt] * blend[:, None]
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    amp = amp_dir[k] * (1 - blend) + amp_dir[nxt] * blend
    amp = np.minimum(amp, max_accel / (2 * np.pi * freq) ** 2)
    ease = minimum_jerk(np.minimum(1.0, np.minimum(rel, T - rel) / 2.0).clip(0.0, 1.0))
    disp = (amp * ease * np.sin(phase))[:, None] * d
    position = centre[None, :] + disp
    base = NATURAL_GRIP
    quat = natural_orientation(rng, rel, rate_hz, base_quat=base, mean_rate=8 * DEG, max_rate=40 * DEG, f_band=(0.05, 0.5))
    meta = {
        "band_hz": list(band_hz),
        "directions": names,
        "centre_W": centre.tolist(),
        "amplitude_by_direction_m": amp_dir.tolist(),
        "max_accel_m_per_s2": max_accel,
    }
    return _finish(rng, t, rate_hz, position, quat, "local_dynamic", None, meta)


def figure_eight(
    rng: np.random.Generator,
    reach: Reach,
    duration_s: float = 30.0,
    *,
    rate_hz: float = DEFAULT_RATE_HZ,
    width: float = 0.08,
    height: float = 0.04,
    period_range_s: tuple[float, float] = FIGURE_EIGHT_PERIODS_S,
    t0: float = 0.0,
) -> HandTrajectory:
    """Figure-eight (the paper's test set 3, §VI-D): an infinity shape near the workspace centre at varied speed.

    A Gerono-free lemniscate ``(w/2 sin φ, h/2 sin 2φ)`` in a plane tilted randomly by up to 20° from
    horizontal; the period changes smoothly between ``period_range_s`` (slow → fast → slow).
    Stored as protocol ``other`` with label ``figure_eight``.
    """
    t = clock(duration_s, rate_hz, t0)
    rel = t - t0
    T = rel[-1]
    slow, fast = period_range_s
    shape = 0.5 - 0.5 * np.cos(2 * np.pi * rel / T)  # 0 → 1 → 0
    freq = 1.0 / (slow + (fast - slow) * shape)
    phase = 2 * np.pi * np.cumsum(freq) / rate_hz
    ease = minimum_jerk(np.minimum(1.0, np.minimum(rel, T - rel) / 1.5).clip(0.0, 1.0))
    centre = reach.centre()
    tilt = rng.uniform(-20, 20) * DEG
    yaw = rng.uniform(-30, 30) * DEG
    u = np.array([math.cos(yaw), math.sin(yaw), 0.0])
    v = np.array([-math.sin(yaw) * math.cos(tilt), math.cos(yaw) * math.cos(tilt), math.sin(tilt)])
    scale = min(
        1.0,
        0.8 * min(reach.free_distance(centre, u), reach.free_distance(centre, -u)) / (width / 2),
        0.8 * min(reach.free_distance(centre, v), reach.free_distance(centre, -v)) / (height / 2),
    )
    a = ease * scale
    position = centre + (a * width / 2 * np.sin(phase))[:, None] * u + (a * height / 2 * np.sin(2 * phase))[:, None] * v
    quat = natural_orientation(rng, rel, rate_hz, base_quat=NATURAL_GRIP, mean_rate=6 * DEG, max_rate=30 * DEG)
    meta = {
        "width_m": width * scale,
        "height_m": height * scale,
        "period_range_s": list(period_range_s),
        "plane_tilt_rad": tilt,
        "plane_yaw_rad": yaw,
    }
    return _finish(rng, t, rate_hz, position, quat, "other", "figure_eight", meta)


def surface_circles(
    rng: np.random.Generator,
    reach: Reach,
    surface_z: float,
    duration_s: float = 30.0,
    *,
    rate_hz: float = DEFAULT_RATE_HZ,
    radius: float = 0.03,
    depth_m: float = 0.0025,
    period_range_s: tuple[float, float] = SURFACE_PERIODS_S,
    approach_s: float = 1.5,
    t0: float = 0.0,
) -> HandTrajectory:
    """Frictionless-surface protocol (paper §V-D): circles in the xy plane on the surface, pressing lightly.

    The hand starts 1 cm above the surface at the workspace centre, descends to ``depth_m`` below it
    (a light press: ≈ 1 N at the paper's rendered stiffness), circles with a period falling from
    ``period_range_s[0]`` to ``period_range_s[1]`` (low to high speed) with a slowly varying depth,
    then lifts off. Positions are kinematic: the contact force emerges in the twin's rendering loop.
    """
    t = clock(duration_s, rate_hz, t0)
    rel = t - t0
    T = rel[-1]
    centre = reach.centre().copy()
    centre[2] = surface_z
    r = min(
        radius,
        0.8
        * min(
            reach.free_distance(centre - [0, 0, depth_m * 2], d)
            for d in (np.array([1.0, 0, 0]), np.array([-1.0, 0, 0]), np.array([0, 1.0, 0]), np.array([0, -1.0, 0]))
        ),
    )
    slow, fast = period_range_s
    circ = np.clip((rel - approach_s) / (T - 2 * approach_s), 0.0, 1.0)
    freq = 1.0 / (slow + (fast - slow) * circ)
    phase = 2 * np.pi * np.cumsum(freq * (circ > 0)) / rate_hz
    grow = minimum_jerk(np.minimum(1.0, np.minimum(rel - approach_s, T - approach_s - rel) / 1.0).clip(0.0, 1.0))
    x = centre[0] + grow * r * (np.cos(phase) - 1.0)
    y = centre[1] + grow * r * np.sin(phase)
    depth = depth_m * (1.0 + 0.2 * smooth_noise(rng, rel, 0.1, 0.5)[:, 0].clip(-2, 2) / 2)
    down = minimum_jerk(np.minimum(rel / approach_s, (T - rel) / approach_s).clip(0.0, 1.0))
    z = surface_z + 0.01 * (1 - down) - depth * down
    position = np.stack([x, y, z], axis=1)
    quat = natural_orientation(rng, rel, rate_hz, base_quat=NATURAL_GRIP, mean_rate=4 * DEG, max_rate=16 * DEG)
    meta = {"radius_m": r, "depth_m": depth_m, "period_range_s": list(period_range_s), "surface_z_m": surface_z}
    return _finish(rng, t, rate_hz, position, quat, "frictionless_surface", None, meta)


def surface_presses(
    rng: np.random.Generator,
    reach: Reach,
    surface_z: float,
    duration_s: float = 30.0,
    *,
    rate_hz: float = DEFAULT_RATE_HZ,
    presses: int | None = None,
    press_speed: float = PRESS_SPEED,
    above_m: float = 0.01,
    edge_margin: float = 0.002,
    t0: float = 0.0,
) -> HandTrajectory:
    """Stiffness protocol (paper §V-E): repeated presses down (−z) into the surface up to the workspace edge.

    Each press starts ``above_m`` above the surface at the workspace centre, goes down at about
    ``press_speed`` (m/s) to 85–100 % of the free distance to the workspace edge (less ``edge_margin``),
    and comes back up faster; minimum-jerk strokes, a short rest above the surface between presses.
    Whether the force plateaus (saturation) or drops (safety cut-off) before the edge emerges in the
    twin; the hand path is kinematic.
    """
    t = clock(duration_s, rate_hz, t0)
    rel = t - t0
    centre = reach.centre().copy()
    top = centre.copy()
    top[2] = surface_z + above_m
    edge = reach.free_distance(top, np.array([0.0, 0.0, -1.0]), limit=0.25, steps=1000)
    full = max(edge - edge_margin, above_m + 0.002)
    depth_frac: list[float] = []
    segments: list[tuple[float, float, float, float]] = []  # (start_time, duration, z_from, z_to)
    now = 0.5
    while True:
        frac = rng.uniform(0.85, 1.0)
        stroke = full * frac
        down = stroke / press_speed
        up = 0.5 * down
        if now + down + up + 0.5 > rel[-1] or (presses is not None and len(depth_frac) >= presses):
            break
        segments.append((now, down, 0.0, -stroke))
        segments.append((now + down, up, -stroke, 0.0))
        depth_frac.append(frac)
        now += down + up + rng.uniform(0.4, 0.8)
    dz = np.zeros_like(rel)
    for start, dur, a, b in segments:
        m = (rel >= start) & (rel < start + dur)
        dz[m] = a + (b - a) * minimum_jerk((rel[m] - start) / dur)
    position = np.repeat(top[None, :], len(rel), axis=0)
    position[:, 2] += dz
    quat = natural_orientation(rng, rel, rate_hz, base_quat=NATURAL_GRIP, mean_rate=3 * DEG, max_rate=12 * DEG)
    meta = {
        "surface_z_m": surface_z,
        "edge_distance_m": edge,
        "press_depths_m": [full * f - above_m for f in depth_frac],
        "press_count": len(depth_frac),
        "press_speed_m_per_s": press_speed,
    }
    return _finish(rng, t, rate_hz, position, quat, "stiffness", None, meta)


# --- rig calibration trials (paper §III-C, Appendix) -----------------------------------------------


def handle_rotation(
    rng: np.random.Generator,
    duration_s: float = 40.0,
    *,
    rate_hz: float = DEFAULT_RATE_HZ,
    centre_W: tuple[float, float, float] = (0.0, 0.0, 0.35),
    t0: float = 0.0,
) -> HandTrajectory:
    """Handle calibration trial (paper §III-C, Fig. 3): the unattached end-effector slowly rotated in the air.

    The handle z-axis sweeps the whole sphere of directions (tilt 0 → 180° → 0 while the heading turns
    three times) and the handle spins about its own axis, so gravity is seen from every direction in the
    body frame (what the sphere fits of eqs. 1–3 need); the position drifts by a few cm.
    """
    t = clock(duration_s, rate_hz, t0)
    rel = t - t0
    T = rel[-1]
    tilt = math.pi * (0.5 - 0.5 * np.cos(2 * np.pi * rel / T))
    heading = 2 * np.pi * 3 * minimum_jerk(rel / T)
    spin = 2 * np.pi * 1.5 * minimum_jerk(rel / T) + rng.uniform(0, 2 * np.pi)
    qz = quat_from_axis_angle(np.array([0.0, 0.0, 1.0]), heading)
    qy = quat_from_axis_angle(np.array([0.0, 1.0, 0.0]), tilt)
    qs = quat_from_axis_angle(np.array([0.0, 0.0, 1.0]), spin)
    quat = quat_normalize(quat_multiply(quat_multiply(qz, qy), qs))
    drift = 0.02 * smooth_noise(rng, rel, 0.02, 0.1, dims=3) * minimum_jerk(np.minimum(rel, T - rel).clip(0, 1))[:, None]
    position = np.asarray(centre_W, float)[None, :] + drift
    return _finish(rng, t, rate_hz, position, quat, "rig.handle_calibration", None, {"centre_W": list(centre_W)})


def baseline_wander(
    rng: np.random.Generator,
    duration_s: float = 30.0,
    *,
    rate_hz: float = DEFAULT_RATE_HZ,
    centre_W: tuple[float, float, float] = (0.15, 0.0, 0.25),
    t0: float = 0.0,
) -> HandTrajectory:
    """Baseline vibration trial (paper §VI-C): the free-space motion with the handle but no device attached."""
    return free_space_wander(
        rng, None, duration_s, rate_hz=rate_hz, t0=t0, protocol="rig.baseline_vibration", centre_W=np.asarray(centre_W, float)
    )
