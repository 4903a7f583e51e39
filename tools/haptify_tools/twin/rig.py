"""The virtual rig: sensor models that turn true motion and loads into raw streams (design §4; paper §II, §III, Appendix).

Every model is a pure function of the true signals, its parameters and a seeded random generator, and
returns the columns of one standard stream kind (``schemas/1.0/stream-kinds.json``). Raw means raw
(spec §2.6): the handle F/T reports, in its own frame S, the force and torque the connector side
exerts on the sensor (torque about S's origin) plus its bias — the sign convention of the reference's
``haptify.processing.calibration`` (spec §6.1): at rest and unattached it reads ``b_F + m g_S``. The accelerometer
reads specific force ``R_WAᵀ(a − g_W)`` (+g up at rest) plus bias, clipped to its range and quantised.
The force plate's four corner sensors each report, in their own frame, the force the plate presses
onto them (a weight on the plate reads negative ``fz``).

Rig-side effects of the twin (``sensor.bias``, ``handle.connector_mass``) and the accelerometer noise
floor come from the twin file's ``rig`` section; noise levels, rates and geometry of the instruments
are :class:`RigConfig` (numbers and their sources below).
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass

import numpy as np
from scipy import signal

from haptify.formats.conventions import (
    GRAVITY_W,
    STANDARD_GRAVITY,
    quat_conjugate,
    quat_from_axis_angle,
    quat_multiply,
    quat_normalize,
    quat_rotate,
    quat_to_matrix,
)
from haptify_tools.twin.hand_path import band_noise, derivative, rotation_vector_to_quat

DEG = math.pi / 180.0


@dataclass
class RigConfig:
    """Instrument parameters of the virtual rig (SI units). Defaults model the paper's Haptify rig.

    Sources: rates paper §V; mocap noise 0.15 mm (paper §III-A, Merriaux et al.); F/T noise of the ATI
    Mini27 Ti (resolution 1/32 N, 1/1333 N·m at SI-80-4; the paper's calibration-fit RMS 0.008 N and
    0.0002 N·m after low-pass filtering, §III-C); Mini40 plate corners (resolution 1/100 N); the MPU-9250
    at ±4 g full scale with 16-bit output (LSB = 8 g / 2¹⁶), range ±40 m/s² (paper Table I); plate
    modes 205 / 206 / 182 Hz (paper Appendix, Fig. 12); plate weight 160 N (paper §II); corner
    centre-to-centre distance L = 0.6 m (paper Appendix). The corner sensors' gain and mounting
    errors (2 %, 3 mm) are chosen so the COP error comes out near the paper's 4.8 ± 3.8 mm.
    """

    mocap_rate_hz: float = 100.0
    mocap_noise_m: float = 0.15e-3  # per axis, per marker
    mocap_marker_baseline_m: float = 0.03  # typical marker spread on a rigid body (sets pose angle noise)
    occlusion_rate_per_s: float = 0.02  # gaps per second per marker
    occlusion_mean_s: float = 0.12  # mean gap length, s
    ft_rate_hz: float = 1000.0
    ft_force_noise_N: float = 0.02  # per axis, white, 1 kHz
    ft_torque_noise_Nm: float = 0.0005
    ft_pose_position_m: tuple[float, float, float] = (0.0, 0.0, -0.03)  # S in the handle frame H
    ft_pose_yaw_rad: float = 90 * DEG  # S rotated about H's z axis
    ft_range_force_N: tuple[float, float, float] = (80.0, 80.0, 160.0)  # ATI Mini27 Ti SI-80-4
    ft_range_torque_Nm: tuple[float, float, float] = (4.0, 4.0, 2.0)
    ft_gain: float = 1.0  # the F/T's calibration gain error: its whole reading × ft_gain
    ft_gain_drift_sd: float = 0.0  # relative sd of that gain's drift from trial to trial
    accel_rate_hz: float = 2000.0
    accel_white_noise_m_per_s2: float = 0.0  # extra white noise on top of the twin's noise floor
    accel_range_m_per_s2: float = 40.0
    accel_lsb_m_per_s2: float = 8 * STANDARD_GRAVITY / 65536
    accel_pose_position_m: tuple[float, float, float] = (0.0, 0.0, -0.05)
    accel_pose_yaw_rad: float = -90 * DEG
    plate_rate_hz: float = 1000.0
    plate_half_side_m: float = 0.3
    plate_sensor_depth_m: float = 0.02  # corner sensor origins below the plate's top surface
    plate_weight_N: float = 160.0
    plate_modes_hz: tuple[float, float, float] = (205.0, 206.0, 182.0)
    plate_damping_ratio: float = 0.03
    plate_gain_sd: float = 0.02  # per corner and axis: relative gain error of the corner sensors
    plate_position_sd_m: float = 0.003  # per corner, x and y: mounting error vs the described position
    plate_force_noise_N: float = 0.01
    plate_torque_noise_Nm: float = 0.0003
    plate_range_force_N: tuple[float, float, float] = (40.0, 40.0, 120.0)  # ATI Mini40 SI-40-2 (per corner)
    plate_range_torque_Nm: tuple[float, float, float] = (2.0, 2.0, 2.0)
    sync_rate_hz: float = 1000.0
    sync_pulse_start_s: float = 0.3  # after the trial start
    sync_pulse_length_s: float = 0.1
    clock_offsets: bool = False  # give the accelerometer and mocap recorders their own clocks
    max_clock_offset_s: float = 0.02

    def to_dict(self) -> dict:
        return {k: list(v) if isinstance(v, tuple) else v for k, v in asdict(self).items()}


# --- geometry -------------------------------------------------------------------------------------


def yaw_quat(yaw: float) -> np.ndarray:
    """Unit quaternion of a rotation by ``yaw`` rad about z ([w, x, y, z], spec §1.3)."""
    return quat_from_axis_angle(np.array([0.0, 0.0, 1.0]), np.array(yaw))


def corner_positions(cfg: RigConfig) -> np.ndarray:
    """Corner sensor origins ``(4, 3)`` in W: c1 (+,+), c2 (−,+), c3 (−,−), c4 (+,−) (paper Appendix numbering)."""
    h = cfg.plate_half_side_m
    return np.array(
        [
            [h, h, -cfg.plate_sensor_depth_m],
            [-h, h, -cfg.plate_sensor_depth_m],
            [-h, -h, -cfg.plate_sensor_depth_m],
            [h, -h, -cfg.plate_sensor_depth_m],
        ]
    )


def corner_quaternions(cfg: RigConfig) -> np.ndarray:
    """Corner sensor frames in W: each turned about z so its cable points outwards (45°, 135°, 225°, 315°).
    The ``rig.force_plate.corners`` poses of spec §2.4."""
    return np.array([yaw_quat(a * DEG) for a in (45.0, 135.0, 225.0, 315.0)])


def marker_layout(links: list[str], link_lengths: list[float]) -> dict[str, np.ndarray]:
    """Marker positions ``(3, 3)`` in each rigid body's frame: the base, every arm link, the handle (m).

    Arm links use distal DH frames (the link lies along −x from the frame origin), so the three markers
    sit at 25 %, 50 % and 75 % of its length, lifted off the axis by 12–18 mm so they are not collinear.
    """
    layout: dict[str, np.ndarray] = {"base": np.array([[0.06, 0.05, 0.02], [0.06, -0.05, 0.02], [-0.04, 0.0, 0.05]])}
    for name, a in zip(links, link_lengths):
        a = max(abs(a), 0.04)
        layout[name] = np.array([[-0.25 * a, 0.012, 0.015], [-0.5 * a, -0.015, 0.012], [-0.75 * a, 0.014, -0.018]])
    layout["handle"] = np.array([[0.0, 0.015, -0.06], [0.015, -0.01, -0.07], [-0.015, -0.01, -0.08]])
    return layout


def rig_description(cfg: RigConfig, layout: dict[str, np.ndarray], extra_markers: tuple[str, ...] = ()) -> dict:
    """The standard rig description (spec §2.4) of the virtual rig: plate, handle sensors, motion capture."""
    cq = corner_quaternions(cfg)
    corners = [
        {"id": f"c{i + 1}", "pose": {"position": p.tolist(), "quaternion": q.tolist()}}
        for i, (p, q) in enumerate(zip(corner_positions(cfg), cq))
    ]
    bodies = [{"name": body, "markers": marker_names(body, len(pts))} for body, pts in layout.items()]
    markers = [m for b in bodies for m in b["markers"]] + list(extra_markers)
    return {
        "name": "haptify virtual rig",
        "force_plate": {
            "size_m": [2 * cfg.plate_half_side_m] * 2,
            "corners": corners,
            "corner_range": {"force_N": list(cfg.plate_range_force_N), "torque_Nm": list(cfg.plate_range_torque_Nm)},
        },
        "handle": {
            "ft_sensor": {
                "pose": {"position": list(cfg.ft_pose_position_m), "quaternion": yaw_quat(cfg.ft_pose_yaw_rad).tolist()},
                "range": {"force_N": list(cfg.ft_range_force_N), "torque_Nm": list(cfg.ft_range_torque_Nm)},
                "model": "ATI Mini27 Ti SI-80-4 (simulated)",
            },
            "accelerometer": {
                "pose": {"position": list(cfg.accel_pose_position_m), "quaternion": yaw_quat(cfg.accel_pose_yaw_rad).tolist()},
                "range": {"accel_m_per_s2": [cfg.accel_range_m_per_s2] * 3},
                "model": "MPU-9250 (simulated)",
            },
        },
        "motion_capture": {
            "system": "Vicon (simulated)",
            "rate_hz": cfg.mocap_rate_hz,
            "rigid_bodies": bodies,
            "markers": markers,
        },
    }


def marker_names(body: str, count: int) -> list[str]:
    """Labels of a rigid body's markers: ``<body>_m1`` … (ids per spec §2.1)."""
    return [f"{body}_m{k + 1}" for k in range(count)]


# --- sampling helpers -----------------------------------------------------------------------------


def decimation(src_rate: float, dst_rate: float) -> int:
    """The integer step that takes a ``src_rate`` clock to ``dst_rate`` (ValueError when not an integer)."""
    step = src_rate / dst_rate
    if abs(step - round(step)) > 1e-9 or round(step) < 1:
        raise ValueError(f"{dst_rate} Hz is not an integer division of {src_rate} Hz")
    return int(round(step))


def occlusion_mask(rng: np.random.Generator, n: int, rate_hz: float, gaps_per_s: float, mean_gap_s: float) -> np.ndarray:
    """Boolean mask (True = occluded) of one marker: Poisson gap starts, exponential gap lengths ≥ 1 sample."""
    mask = np.zeros(n, dtype=bool)
    duration = n / rate_hz
    count = rng.poisson(gaps_per_s * duration)
    starts = rng.integers(0, n, count)
    lengths = np.maximum(1, np.round(rng.exponential(mean_gap_s, count) * rate_hz).astype(int))
    for s, ln in zip(starts, lengths):
        mask[s : s + ln] = True
    return mask


# --- motion capture (paper §III-A) ----------------------------------------------------------------


def mocap_markers(
    rng: np.random.Generator, cfg: RigConfig, positions: dict[str, np.ndarray]
) -> tuple[dict, dict[str, np.ndarray]]:
    """Noisy, occluded marker positions (``markers`` columns without ``t``) and each marker's occlusion mask.
    Spec §2.6; NaN for occlusion as §2.7.

    ``positions`` maps a marker label to its true positions ``(N, 3)`` (m, W) at the mocap rate.
    """
    cols: dict[str, np.ndarray] = {}
    masks: dict[str, np.ndarray] = {}
    for name, p in positions.items():
        n = len(p)
        noisy = p + rng.normal(0.0, cfg.mocap_noise_m, p.shape)
        gap = occlusion_mask(rng, n, cfg.mocap_rate_hz, cfg.occlusion_rate_per_s, cfg.occlusion_mean_s)
        noisy[gap] = np.nan
        masks[name] = gap
        for k, axis in enumerate("xyz"):
            cols[f"{name}_{axis}"] = noisy[:, k]
    return cols, masks


def pose_noise(
    rng: np.random.Generator, cfg: RigConfig, position: np.ndarray, quaternion: np.ndarray, markers: int = 3
) -> tuple[np.ndarray, np.ndarray]:
    """A rigid body's pose as motion capture estimates it from ``markers`` noisy markers.

    Position noise σ/√n per axis; orientation noise a rotation vector with σ/(baseline·√n) rad per axis.
    """
    sp = cfg.mocap_noise_m / math.sqrt(markers)
    sr = sp / cfg.mocap_marker_baseline_m
    pos = position + rng.normal(0.0, sp, position.shape)
    q = quat_normalize(quat_multiply(quaternion, rotation_vector_to_quat(rng.normal(0.0, sr, position.shape))))
    q *= np.where(q[:, :1] < 0, -1.0, 1.0)
    return pos, q


def pose_columns(prefix: str, position: np.ndarray, quaternion: np.ndarray, occluded: np.ndarray) -> dict:
    """Columns ``<prefix>px … <prefix>qz`` of a pose, NaN where ``occluded``.
    Positions in m, unit quaternions; spec §2.6."""
    pos = position.copy()
    q = quaternion.copy()
    pos[occluded] = np.nan
    q[occluded] = np.nan
    cols = {f"{prefix}p{a}": pos[:, k] for k, a in enumerate("xyz")}
    cols.update({f"{prefix}q{a}": q[:, k] for k, a in enumerate("wxyz")})
    return cols


# --- handle F/T (paper §II, §III-C) ---------------------------------------------------------------


@dataclass
class HandleLoads:
    """What the rig needs to model the handle sensors, on the F/T clock: the device's wrench on the hand.
    The reported wrench of spec §1.5.

    ``force_W`` (N) acts at the gimbal centre, ``torque_W`` (N·m) is about the gimbal centre, both in W.
    """

    force_W: np.ndarray
    torque_W: np.ndarray


def connector_motion(
    cfg: RigConfig, *, position_W: np.ndarray, quaternion_W: np.ndarray, rate_hz: float, connector_com_S: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """On the F/T clock: the sensor's orientation ``q_WS`` and origin ``p_S`` (m, W), the connector's centre of
    mass from ``p_S`` (m, W) and that centre's acceleration ``a_c`` (m/s², W; finite differences of the
    rigid-body path). ``m a_c`` is the connector's inertial force, which the reported force keeps (spec §6.1)."""
    step = decimation(rate_hz, cfg.ft_rate_hz)
    q_hs = yaw_quat(cfg.ft_pose_yaw_rad)
    p_hs = np.asarray(cfg.ft_pose_position_m, float)
    q_ws = quat_multiply(quaternion_W, np.broadcast_to(q_hs, quaternion_W.shape))
    p_s = position_W + quat_rotate(quaternion_W, np.broadcast_to(p_hs, position_W.shape))
    r_c_W = quat_rotate(q_ws, np.broadcast_to(np.asarray(connector_com_S, float), position_W.shape))
    a_c = derivative(p_s + r_c_W, rate_hz, 2)
    return q_ws[::step], p_s[::step], r_c_W[::step], a_c[::step]


def handle_wrench(
    rng: np.random.Generator,
    cfg: RigConfig,
    *,
    position_W: np.ndarray,
    quaternion_W: np.ndarray,
    rate_hz: float,
    loads: HandleLoads | None,
    bias_force: np.ndarray,
    bias_torque: np.ndarray,
    connector_mass: float,
    connector_com_S: np.ndarray,
    gain: float = 1.0,
) -> dict:
    """Raw ``handle_wrench`` columns at ``cfg.ft_rate_hz`` (spec §2.6; sign convention of spec §6.1).

    ``position_W``/``quaternion_W`` are the handle pose on the examiner clock (``rate_hz``, a multiple of
    the F/T rate); ``loads`` are on the F/T clock (None: unattached handle). The connector (mass m, centre
    of mass r in S) transmits ``F_dev + m (g − a_c)``, with ``a_c`` its centre of mass's acceleration:

        F_S = R_WSᵀ (F_dev + m (g − a_c)) + b_F + n_F
        τ_S = R_WSᵀ (τ_dev + (p_H − p_S) × F_dev + (R_WS r) × m (g − a_c)) + b_τ + n_τ

    ``gain`` is the sensor's calibration error: its whole reading (load, bias and noise, all of which pass
    through the sensor's calibration matrix) comes out multiplied by it (1 = a perfectly calibrated sensor).
    """
    q_ws, p_s, r_c_W, a_c = connector_motion(
        cfg, position_W=position_W, quaternion_W=quaternion_W, rate_hz=rate_hz, connector_com_S=connector_com_S
    )
    p_h = position_W[:: decimation(rate_hz, cfg.ft_rate_hz)]
    n = len(q_ws)
    conn = connector_mass * (GRAVITY_W[None, :] - a_c)
    force = conn.copy()
    torque = np.cross(r_c_W, conn)
    if loads is not None:
        if len(loads.force_W) != n:
            raise ValueError(f"loads have {len(loads.force_W)} samples, the F/T clock {n}")
        force += loads.force_W
        torque += loads.torque_W + np.cross(p_h - p_s, loads.force_W)
    inv = quat_conjugate(q_ws)
    f_s = quat_rotate(inv, force) + bias_force + rng.normal(0.0, cfg.ft_force_noise_N, (n, 3))
    t_s = quat_rotate(inv, torque) + bias_torque + rng.normal(0.0, cfg.ft_torque_noise_Nm, (n, 3))
    if gain != 1.0:
        f_s, t_s = gain * f_s, gain * t_s
    return {"fx": f_s[:, 0], "fy": f_s[:, 1], "fz": f_s[:, 2], "tx": t_s[:, 0], "ty": t_s[:, 1], "tz": t_s[:, 2]}


# --- accelerometer (paper §II, §IV-C) --------------------------------------------------------------


def noise_floor(rng: np.random.Generator, n: int, rate_hz: float, floor) -> np.ndarray:
    """The rig's acceleration noise floor ``(n, 3)`` in m/s² on each world axis (twin ``rig.accel_floor``).

    Two band-limited Gaussian components with RMS ``low_rms`` in ``low_band_hz`` and ``high_rms`` in
    ``high_band_hz`` per axis (paper §VI-C: 0.0332 m/s² RMS, centroid 108.25 Hz without a device).
    """
    nyq = rate_hz / 2
    out = np.zeros((n, 3))
    for rms, band in ((floor.low_rms_m_per_s2, floor.low_band_hz), (floor.high_rms_m_per_s2, floor.high_band_hz)):
        if rms > 0:
            out += rms * band_noise(rng, n, rate_hz, band[0], min(band[1], nyq), dims=3)
    return out


def specific_force(
    cfg: RigConfig,
    *,
    position_W: np.ndarray,
    quaternion_W: np.ndarray,
    rate_hz: float,
    vibration_W: np.ndarray | None,
    floor_W: np.ndarray | None,
) -> np.ndarray:
    """What a perfect accelerometer reads ``(n, 3)`` at ``cfg.accel_rate_hz``: ``R_WAᵀ (a − g_W + v + f)``.

    ``a`` is the acceleration of the accelerometer's origin (finite differences of the rigid-body path),
    ``v`` the device vibration (W, physics ``device_vibration``) and ``f`` the rig's noise floor (W, physics
    ``rig_accel_floor``: the table's own vibration), both on the accelerometer clock (None: absent); m/s².
    """
    step = decimation(rate_hz, cfg.accel_rate_hz)
    q_ha = yaw_quat(cfg.accel_pose_yaw_rad)
    p_ha = np.asarray(cfg.accel_pose_position_m, float)
    p_a = position_W + quat_rotate(quaternion_W, np.broadcast_to(p_ha, position_W.shape))
    acc = derivative(p_a, rate_hz, 2)[::step]
    q_wa = quat_multiply(quaternion_W[::step], np.broadcast_to(q_ha, quaternion_W[::step].shape))
    n = len(acc)
    total = acc - GRAVITY_W[None, :]
    for name, extra in (("vibration", vibration_W), ("noise floor", floor_W)):
        if extra is not None:
            if len(extra) != n:
                raise ValueError(f"{name} has {len(extra)} samples, the accelerometer clock {n}")
            total = total + extra
    return quat_rotate(quat_conjugate(q_wa), total)


def handle_accel(rng: np.random.Generator, cfg: RigConfig, *, specific_force_A: np.ndarray, bias: np.ndarray) -> dict:
    """Raw ``handle_accel`` columns from a perfect accelerometer's reading ``specific_force_A`` (:func:`specific_force`):
    ``a_A + b_a + n`` (``n``: ``accel_white_noise``), clipped to ``±accel_range`` and quantised to ``accel_lsb``."""
    a_s = specific_force_A + bias
    if cfg.accel_white_noise_m_per_s2 > 0:
        a_s = a_s + rng.normal(0.0, cfg.accel_white_noise_m_per_s2, a_s.shape)
    a_s = np.clip(a_s, -cfg.accel_range_m_per_s2, cfg.accel_range_m_per_s2)
    if cfg.accel_lsb_m_per_s2 > 0:
        a_s = np.round(a_s / cfg.accel_lsb_m_per_s2) * cfg.accel_lsb_m_per_s2
    return {"ax": a_s[:, 0], "ay": a_s[:, 1], "az": a_s[:, 2]}


# --- force plate (paper §II, §III-B, Appendix) ----------------------------------------------------


def plate_mode_filter(f_hz: float, zeta: float, rate_hz: float) -> tuple[np.ndarray, np.ndarray]:
    """Digital 2nd-order low-pass with unit DC gain and its resonance at ``f_hz`` (prewarped bilinear)."""
    w = 2 * rate_hz * math.tan(math.pi * f_hz / rate_hz)
    b, a = signal.bilinear([w * w], [1.0, 2 * zeta * w, w * w], fs=rate_hz)
    return b, a


def corner_loads(positions: np.ndarray, force_W: np.ndarray, moment_W: np.ndarray) -> np.ndarray:
    """Share a load wrench among four corner supports of a rigid plate → ``(N, 4, 3)`` forces in W.

    ``positions (4, 3)``: the supports' true positions (m, W); ``force_W``/``moment_W`` ``(N, 3)``: what
    the load applies to the plate, moment about the W origin. Equal supports: horizontal force shared
    equally plus tangential forces for the vertical moment; vertical forces linear in the support
    position (``a + b x + c y``), solved so the four corner forces reproduce the whole wrench exactly
    (the horizontal forces act at the supports' depth).
    """
    x, y, z = positions[:, 0], positions[:, 1], positions[:, 2]
    fx, fy, fz = force_W.T
    xm, ym = x.mean(), y.mean()
    k = (moment_W[:, 2] - xm * fy + ym * fx) / np.sum((x - xm) * x + (y - ym) * y)
    out = np.empty((len(force_W), 4, 3))
    out[:, :, 0] = fx[:, None] / 4 - k[:, None] * (y - ym)[None, :]
    out[:, :, 1] = fy[:, None] / 4 + k[:, None] * (x - xm)[None, :]
    a_mat = np.array([[4.0, x.sum(), y.sum()], [x.sum(), (x * x).sum(), (x * y).sum()], [y.sum(), (x * y).sum(), (y * y).sum()]])
    rhs = np.stack([fz, out[:, :, 0] @ z - moment_W[:, 1], moment_W[:, 0] + out[:, :, 1] @ z], axis=1)
    abc = np.linalg.solve(a_mat, rhs.T).T
    out[:, :, 2] = abc[:, :1] + abc[:, 1:2] * x[None, :] + abc[:, 2:3] * y[None, :]
    return out


@dataclass
class PlateErrors:
    """The force plate's hidden imperfections: true corner positions ``(4, 3)`` and gains ``(4, 3)``.
    Positions in m, gains dimensionless."""

    positions: np.ndarray
    gains: np.ndarray

    @classmethod
    def draw(cls, rng: np.random.Generator, cfg: RigConfig) -> "PlateErrors":
        """Random mounting and gain errors with the configured standard deviations."""
        pos = corner_positions(cfg).copy()
        pos[:, :2] += rng.normal(0.0, cfg.plate_position_sd_m, (4, 2))
        return cls(positions=pos, gains=1.0 + rng.normal(0.0, cfg.plate_gain_sd, (4, 3)))

    @classmethod
    def ideal(cls, cfg: RigConfig) -> "PlateErrors":
        return cls(positions=corner_positions(cfg), gains=np.ones((4, 3)))


def plate_wrench(
    rng: np.random.Generator,
    cfg: RigConfig,
    *,
    force_W: np.ndarray,
    moment_W: np.ndarray,
    bias_force: np.ndarray,
    errors: PlateErrors | None = None,
) -> dict:
    """Raw ``plate_wrench`` columns at ``cfg.plate_rate_hz`` (spec §2.6).

    ``force_W``/``moment_W`` ``(N, 3)``: every external load on the plate (device base reaction, weights,
    impacts), moment about the W origin, on the plate clock. The plate's own weight is added; each
    world axis of the corner loads passes through the plate mode of that axis (a unit-DC-gain
    resonance at ``plate_modes_hz``, started at rest under the first sample's load); each corner then
    reports in its own frame with its gain error (``errors``; None = ideal), plus its bias and noise. The corner torques carry only noise (the
    corners carry the plate through point-like contacts).
    """
    n = len(force_W)
    plate = np.zeros((n, 3))
    plate[:, 2] = -cfg.plate_weight_N
    errors = errors or PlateErrors.ideal(cfg)
    loads = corner_loads(errors.positions, force_W + plate, moment_W)
    for axis in range(3):
        b, a = plate_mode_filter(cfg.plate_modes_hz[axis], cfg.plate_damping_ratio, cfg.plate_rate_hz)
        zi = signal.lfilter_zi(b, a)
        for c in range(4):
            x = loads[:, c, axis]
            loads[:, c, axis], _ = signal.lfilter(b, a, x, zi=zi * x[0])
    cols: dict[str, np.ndarray] = {}
    for c, q in enumerate(corner_quaternions(cfg)):
        r = quat_to_matrix(q)
        f = (loads[:, c, :] @ r) * errors.gains[c] + bias_force + rng.normal(0.0, cfg.plate_force_noise_N, (n, 3))
        tq = rng.normal(0.0, cfg.plate_torque_noise_Nm, (n, 3))
        for k, ax in enumerate("xyz"):
            cols[f"c{c + 1}_f{ax}"] = f[:, k]
        for k, ax in enumerate("xyz"):
            cols[f"c{c + 1}_t{ax}"] = tq[:, k]
    return cols


# --- sync and clocks ------------------------------------------------------------------------------


def sync_trigger(cfg: RigConfig, t: np.ndarray, t0: float) -> dict:
    """The ``sync`` column: the multicontact switch closed once, ``sync_pulse_start_s`` after the trial start.
    The ``sync`` kind of spec §2.6, 0 or 1; times in s."""
    start = t0 + cfg.sync_pulse_start_s
    return {"trigger": ((t >= start) & (t < start + cfg.sync_pulse_length_s)).astype(float)}


def clock_offset(rng: np.random.Generator, cfg: RigConfig) -> float:
    """A recorder's clock offset (s): add it to the stream's ``t`` to reach the session clock (spec §2.8)."""
    return float(rng.uniform(-cfg.max_clock_offset_s, cfg.max_clock_offset_s)) if cfg.clock_offsets else 0.0
