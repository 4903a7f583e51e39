"""The virtual examiner: seeded hand trajectories for every protocol (design §4; paper §V, §III-C, Appendix).

Every generator takes a :class:`numpy.random.Generator` and returns samples on a uniform clock
(default 2 kHz, the fastest sensor of the rig, so the accelerometer model can differentiate the path
without interpolation). Positions are of the gimbal centre in the world frame W (m), orientations are
unit quaternions ``[w, x, y, z]`` rotating the handle body frame H to W (spec §1.3).

Where a generator needs the device's reach it asks a :class:`Reach`: joint-limit box in unit
coordinates (``s ∈ [0, 1]³`` mapped through the coupled limits, reference ``configurations_from_unit``),
forward kinematics into W, inverse kinematics and the base-collision clearance of the twin (its TRUE
kinematics: the examiner moves the real device, link-length errors and all).

Protocol limits (paper §V): free-space wandering below 0.16 m/s and 16 °/s (averages ≈ 0.05 m/s and
≈ 4 °/s, §VI-B); local dynamic oscillations from 0.5 to 4 Hz in x, y, z and the diagonals for about
140 s from the workspace centre (§V-C); circles on the rendered surface while pressing lightly (§V-D);
repeated presses until the workspace edge (§V-E); physiological tremor 8–12 Hz on every hand-held path.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Callable

import numpy as np

from haptify.conventions import (
    STANDARD_GRAVITY,
    quat_angle,
    quat_from_axis_angle,
    quat_multiply,
    quat_normalize,
    quat_to_matrix,
)

DEG = math.pi / 180.0
DEFAULT_RATE_HZ = 2000.0

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
TREMOR_BAND_HZ = (8.0, 12.0)  # physiological tremor band
# Tremor acceleration RMS per axis (m/s²). Kept small: the paper's rig-only vibration floor after a 10 Hz
# high-pass is 0.0332 m/s² RMS (§VI-C) and includes the hand, so the tremor must stay below it.
TREMOR_ACCEL_RMS = 0.01
# Tremor rotation RMS per axis (rad): the sensors sit 3–5 cm from the gimbal centre, where 0.002° at 10 Hz
# already gives ≈ 0.007 m/s² of tangential acceleration.
TREMOR_ANGLE_RMS = 0.002 * DEG
# The examiner's natural grip: the handle frame parallel to W. The twins align their gimbals so that every
# gimbal angle is zero in this grip at the centre of the joint-limit box, so a hand that keeps it stays far
# from the gimbal's singularity; the natural orientation changes wander about it.
NATURAL_GRIP = np.array([1.0, 0.0, 0.0, 0.0])


# --- helpers -------------------------------------------------------------------------------------


def clock(duration_s: float, rate_hz: float = DEFAULT_RATE_HZ, t0: float = 0.0) -> np.ndarray:
    """Uniform sample times ``t0 + k / rate_hz`` covering ``duration_s`` seconds (spec §2.6)."""
    n = int(round(duration_s * rate_hz))
    if n < 2:
        raise ValueError(f"duration {duration_s} s at {rate_hz} Hz gives fewer than two samples")
    return t0 + np.arange(n) / rate_hz


def minimum_jerk(s: np.ndarray) -> np.ndarray:
    """The minimum-jerk blend ``10s³ − 15s⁴ + 6s⁵`` of ``s`` clipped to [0, 1] (Flash & Hogan 1985)."""
    s = np.clip(s, 0.0, 1.0)
    return s * s * s * (10.0 - 15.0 * s + 6.0 * s * s)


def smooth_noise(
    rng: np.random.Generator, t: np.ndarray, f_lo: float, f_hi: float, dims: int = 1, components: int = 7
) -> np.ndarray:
    """A smooth random signal ``(len(t), dims)``: a sum of sinusoids with random frequencies in [f_lo, f_hi] Hz.

    Amplitudes fall as 1/f (so motion is dominated by its slow parts, like a hand's); each column is
    scaled to unit RMS over ``t``. Analytic in ``t``, so it can be evaluated on any clock.
    """
    out = np.zeros((len(t), dims))
    for d in range(dims):
        f = rng.uniform(f_lo, f_hi, components)
        ph = rng.uniform(0, 2 * np.pi, components)
        out[:, d] = np.sum(np.sin(2 * np.pi * f[None, :] * t[:, None] + ph[None, :]) / f[None, :], axis=1)
        out[:, d] /= np.sqrt(np.mean(out[:, d] ** 2)) or 1.0
    return out


def band_noise(rng: np.random.Generator, n: int, rate_hz: float, f_lo: float, f_hi: float, dims: int = 1) -> np.ndarray:
    """Gaussian noise ``(n, dims)`` confined to [f_lo, f_hi] Hz by an FFT brick-wall filter, unit RMS per column."""
    white = rng.standard_normal((n, dims))
    spec = np.fft.rfft(white, axis=0)
    f = np.fft.rfftfreq(n, 1.0 / rate_hz)
    spec[(f < f_lo) | (f > f_hi)] = 0.0
    out = np.fft.irfft(spec, n=n, axis=0)
    rms = np.sqrt(np.mean(out**2, axis=0))
    return out / np.where(rms > 0, rms, 1.0)


def derivative(x: np.ndarray, rate_hz: float, order: int = 1) -> np.ndarray:
    """Finite-difference time derivative (second-order accurate, ``numpy.gradient``) along axis 0.
    Units of ``x`` per s^order."""
    for _ in range(order):
        x = np.gradient(x, 1.0 / rate_hz, axis=0)
    return x


def angular_speed(quaternion: np.ndarray, rate_hz: float) -> np.ndarray:
    """Angular speed (rad/s) between consecutive orientations, one value per sample (last repeated)."""
    ang = quat_angle(quaternion[:-1], quaternion[1:]) * rate_hz
    return np.append(ang, ang[-1])


def rotation_vector_to_quat(r: np.ndarray) -> np.ndarray:
    """Quaternions of rotation vectors ``r (N, 3)`` (axis × angle, rad; [w, x, y, z], spec §1.3)."""
    ang = np.linalg.norm(r, axis=-1)
    axis = np.where(ang[:, None] > 1e-15, r / np.where(ang > 1e-15, ang, 1.0)[:, None], [1.0, 0.0, 0.0])
    return quat_from_axis_angle(axis, ang)


def tremor(
    rng: np.random.Generator, n: int, rate_hz: float, accel_rms: float = TREMOR_ACCEL_RMS, angle_rms: float = TREMOR_ANGLE_RMS
) -> tuple[np.ndarray, np.ndarray]:
    """Physiological tremor: displacement ``(n, 3)`` in m and small rotation vectors ``(n, 3)`` in rad.

    Band 8–12 Hz; the displacement is scaled so that its acceleration has ``accel_rms`` (m/s²) per axis.
    """
    if n < 8 or accel_rms == 0 and angle_rms == 0:
        return np.zeros((n, 3)), np.zeros((n, 3))
    disp = band_noise(rng, n, rate_hz, *TREMOR_BAND_HZ, dims=3)
    acc = derivative(disp, rate_hz, 2)
    disp *= accel_rms / np.sqrt(np.mean(acc**2, axis=0))
    rot = band_noise(rng, n, rate_hz, *TREMOR_BAND_HZ, dims=3) * angle_rms
    return disp, rot


# --- trajectories --------------------------------------------------------------------------------


@dataclass
class HandTrajectory:
    """A hand path: gimbal-centre position (m, W) and handle orientation (wxyz, H → W) on a uniform clock.
    Spec §1.3."""

    t: np.ndarray
    position_W: np.ndarray
    quaternion_W: np.ndarray
    rate_hz: float
    protocol: str
    label: str | None = None
    meta: dict = field(default_factory=dict)

    @property
    def duration(self) -> float:
        return float(self.t[-1] - self.t[0] + 1.0 / self.rate_hz)

    def velocity(self) -> np.ndarray:
        """Velocity (m/s, W) by finite differences."""
        return derivative(self.position_W, self.rate_hz)

    def acceleration(self) -> np.ndarray:
        """Acceleration (m/s², W) by finite differences."""
        return derivative(self.position_W, self.rate_hz, 2)

    def speed(self) -> np.ndarray:
        return np.linalg.norm(self.velocity(), axis=1)

    def angular_speed(self) -> np.ndarray:
        return angular_speed(self.quaternion_W, self.rate_hz)


@dataclass
class Reach:
    """What the examiner knows about the device's reach: all in W.

    ``unit_to_W(s)`` maps unit joint coordinates ``s (N, 3) ∈ [0, 1]`` (through the coupled joint
    limits) to gimbal positions in W (NaN where infeasible); ``reachable(p)`` says whether positions
    ``p (N, 3)`` in W are reachable (inverse kinematics within the limits) and free of collisions;
    ``clearance(p)`` is the signed distance (m) of the end-effector from the base (negative inside, +inf
    without collision geometry).
    """

    unit_to_W: Callable[[np.ndarray], np.ndarray]
    reachable: Callable[[np.ndarray], np.ndarray]
    clearance: Callable[[np.ndarray], np.ndarray]

    def collides(self, p_W: np.ndarray) -> np.ndarray:
        """True where gimbal positions ``p_W (N, 3)`` would put the end-effector into the base (clearance < 0)."""
        return self.clearance(p_W) < 0.0

    def radial_stop(self, s: np.ndarray, coarse: int = 16, iterations: int = 14) -> np.ndarray:
        """Gimbal positions (W) for unit joint coordinates ``s``, stopped at the first collision on the way out.

        The examiner moves from the centre of the joint box (``s = ½``, assumed free) straight out (in
        joint space) towards ``s``; where the end-effector meets the base first, the hand stops there
        (coarse march for the first colliding step, then bisection). Points whose way is free are
        returned unchanged. For a collision-free set that is star-shaped about the centre, this maps the
        box's boundary continuously onto the boundary of the reachable set.
        """
        s = np.atleast_2d(np.asarray(s, dtype=float))
        p = self.unit_to_W(s)
        c = np.full(3, 0.5)
        lam = np.linspace(0.0, 1.0, coarse + 1)[1:]
        rays = c[None, None, :] + lam[None, :, None] * (s - c)[:, None, :]
        hit = self.collides(self.unit_to_W(rays.reshape(-1, 3))).reshape(len(s), coarse)
        blocked = hit.any(axis=1)
        if not blocked.any():
            return p
        first = np.argmax(hit[blocked], axis=1)
        lo = np.where(first > 0, lam[np.maximum(first - 1, 0)], 0.0)  # free
        hi = lam[first]  # colliding
        sb = s[blocked]
        for _ in range(iterations):
            mid = 0.5 * (lo + hi)
            h = self.collides(self.unit_to_W(c + mid[:, None] * (sb - c)))
            hi = np.where(h, mid, hi)
            lo = np.where(h, lo, mid)
        p[blocked] = self.unit_to_W(c + lo[:, None] * (sb - c))
        return p

    def centre(self) -> np.ndarray:
        """The workspace centre: the gimbal position at the middle of the joint-limit box (s = ½, ½, ½)."""
        return self.unit_to_W(np.full((1, 3), 0.5))[0]

    def free_distance(self, origin: np.ndarray, direction: np.ndarray, limit: float = 0.2, steps: int = 400) -> float:
        """Distance (m) from ``origin`` along unit ``direction`` to the first unreachable or colliding point."""
        d = np.linspace(0.0, limit, steps + 1)[1:]
        pts = origin[None, :] + d[:, None] * direction[None, :]
        ok = self.reachable(pts)
        bad = np.flatnonzero(~ok)
        return float(d[bad[0] - 1]) if len(bad) and bad[0] > 0 else (0.0 if len(bad) else float(limit))


def reach_from_kinematics(
    kin,
    placement_position=(0.0, 0.0, 0.0),
    placement_quaternion=(1.0, 0.0, 0.0, 0.0),
    clearance_D: Callable[[np.ndarray], np.ndarray] | None = None,
) -> Reach:
    """A :class:`Reach` for a DH chain ``kin`` (reference ``Kinematics``) placed at a pose in W.

    ``clearance_D(p_D)`` is the signed distance (m) of gimbal-centre points in the device frame from the
    base geometry, negative in collision (None: no collision geometry).
    """
    from haptify.kinematics import configurations_from_unit, forward_positions
    from haptify_tools.twin.kinematics import inverse_kinematics

    r_wd = quat_to_matrix(np.asarray(placement_quaternion, float))
    t_wd = np.asarray(placement_position, float)

    def to_D(p_W: np.ndarray) -> np.ndarray:
        return (np.atleast_2d(p_W) - t_wd) @ r_wd

    def unit_to_W(s: np.ndarray) -> np.ndarray:
        q = configurations_from_unit(kin, s)
        return forward_positions(kin, q) @ r_wd.T + t_wd

    def clearance(p_W: np.ndarray) -> np.ndarray:
        p = to_D(p_W)
        return np.full(len(p), np.inf) if clearance_D is None else np.asarray(clearance_D(p), float)

    def reachable(p_W: np.ndarray) -> np.ndarray:
        _, ok = inverse_kinematics(kin, to_D(p_W))
        return ok & ~(clearance(p_W) < 0)

    return Reach(unit_to_W=unit_to_W, reachable=reachable, clearance=clearance)


def reach_from_twin(twin) -> Reach:
    """The :class:`Reach` of a twin (``haptify_tools.twin.model.TwinFile``): its TRUE kinematics, placement and base collision."""
    from haptify_tools.twin.kinematics import collision_clearance, true_kinematics

    return reach_from_kinematics(
        true_kinematics(twin),
        twin.placement.position,
        twin.placement.quaternion,
        clearance_D=lambda p: collision_clearance(twin, p),
    )


def natural_orientation(
    rng: np.random.Generator,
    t: np.ndarray,
    rate_hz: float,
    *,
    base_quat: np.ndarray,
    mean_rate: float,
    max_rate: float,
    f_band: tuple[float, float] = (0.02, 0.25),
) -> np.ndarray:
    """A natural, slowly wandering hand orientation around ``base_quat`` (wxyz).

    The wander is a smooth random rotation vector; its amplitude is set so that the mean angular speed
    is ``mean_rate`` (rad/s) unless that would exceed ``max_rate`` anywhere, in which case the peak is
    held at ``max_rate``. Returns quaternions ``(len(t), 4)``.
    """
    shape = smooth_noise(rng, t, *f_band, dims=3)
    shape_q = rotation_vector_to_quat(shape * 1e-3)
    w = angular_speed(shape_q, rate_hz) / 1e-3  # angular speed per unit amplitude (small-angle)
    scale = min(mean_rate / max(float(np.mean(w)), 1e-12), max_rate / max(float(np.max(w)), 1e-12))
    scale = min(scale, 35 * DEG)  # a wrist wanders, it does not spin
    q = quat_multiply(base_quat[None, :], rotation_vector_to_quat(shape * scale))
    return quat_normalize(q)


def _finish(
    rng: np.random.Generator,
    t: np.ndarray,
    rate_hz: float,
    position: np.ndarray,
    quaternion: np.ndarray,
    protocol: str,
    label: str | None,
    meta: dict,
    *,
    tremor_accel_rms: float = TREMOR_ACCEL_RMS,
    tremor_angle_rms: float = TREMOR_ANGLE_RMS,
) -> HandTrajectory:
    """Add physiological tremor and package a trajectory."""
    disp, rot = tremor(rng, len(t), rate_hz, tremor_accel_rms, tremor_angle_rms)
    q = quat_normalize(quat_multiply(quaternion, rotation_vector_to_quat(rot)))
    meta = {
        **meta,
        "tremor_accel_rms_m_per_s2": tremor_accel_rms,
        "tremor_angle_rms_rad": tremor_angle_rms,
        "tremor_band_hz": list(TREMOR_BAND_HZ),
    }
    return HandTrajectory(
        t=t, position_W=position + disp, quaternion_W=q, rate_hz=rate_hz, protocol=protocol, label=label, meta=meta
    )


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
