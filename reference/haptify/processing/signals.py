"""The calibrated handle signals every benchmark uses (spec §7.5).

A trial's handle force, torque and acceleration on one uniform grid in the world frame: the raw streams
low-passed and resampled (:mod:`haptify.processing.preprocessing`, §7.2), the handle calibration (chapter 6) applied on
the grid with the grid's orientation from motion capture (§7.4).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from haptify.codes import Code
from haptify.errors import fail
from haptify.processing import calibration as cal_mod
from haptify.processing import preprocessing
from haptify.processing.caching import cached, session_of
from haptify.processing.preprocessing import (
    Kinematics,
    lowpass_resample,
    mocap_track,
    nominal_rate,
    orientation_at,
    pose_on_grid,
    table_columns,
    uniform_grid,
)

WRENCH_COLUMNS = ["fx", "fy", "fz", "tx", "ty", "tz"]
ACCEL_COLUMNS = ["ax", "ay", "az"]


# --- the calibrated handle signals (spec §7.5) ------------------------------------------------------


@dataclass
class HandleSignals(Kinematics):
    """A trial's handle signals on one uniform grid, world frame W, SI units (spec §7.5).

    ``force``/``torque``: the wrench the device applies to the hand, torque about the gimbal centre
    (None when the trial has no handle_wrench); ``acceleration``: handle acceleration with bias and
    gravity removed (None without handle_accel). Every array is NaN where ``valid`` is False
    (motion capture unusable there); metrics use ``valid`` and never see those rows.
    """

    trial_id: str
    rate_hz: float
    acceleration: np.ndarray | None
    force: np.ndarray | None
    torque: np.ndarray | None
    valid: np.ndarray

    @property
    def speed(self) -> np.ndarray:
        """|velocity|, m/s."""
        out: np.ndarray = np.linalg.norm(self.velocity, axis=1)
        return out

    @property
    def angular_speed(self) -> np.ndarray:
        """|angular velocity|, rad/s."""
        out: np.ndarray = np.linalg.norm(self.angular_velocity, axis=1)
        return out


def build_handle_signals(ctx_or_session: Any, trial_id: str, rate_hz: float, calibration: Any = None) -> HandleSignals:
    """:func:`handle_signals` without caching the result; ``calibration`` defaults to the session's (spec §6.4).
    With a context, the processed motion capture (§7.4) is the one cached for the trial's other users."""
    session = session_of(ctx_or_session)
    track = mocap_track(ctx_or_session, trial_id)  # reads handle_pose: its span is the track's
    streams = {
        kind: session.read(trial_id, kind)
        for kind in ("handle_wrench", "handle_accel")
        if session.stream(trial_id, kind) is not None
    }
    t0 = max([track.t[0]] + [df["t"].iloc[0] for df in streams.values()])
    t1 = min([track.t[-1]] + [df["t"].iloc[-1] for df in streams.values()])
    grid = uniform_grid(float(t0), float(t1), rate_hz)
    if len(grid) < 2:
        raise fail(
            Code.STREAMS_DO_NOT_OVERLAP,
            f"the handle streams of trial {trial_id!r} do not overlap in time",
            file="session.json",
            expected="overlapping handle_pose, handle_wrench and handle_accel",
            found=[float(t0), float(t1)],
        )
    pose = pose_on_grid(ctx_or_session, trial_id, grid)
    v = pose.valid
    force = torque = accel = None
    if "handle_wrench" in streams or "handle_accel" in streams:
        cal = calibration if calibration is not None else cal_mod.handle_calibration(session)
    if "handle_wrench" in streams:
        w = streams["handle_wrench"]
        raw = lowpass_resample(
            w["t"].to_numpy(), table_columns(w, WRENCH_COLUMNS), grid, preprocessing.PARAMETERS.wrench_cutoff_hz
        )
        force, torque = np.full((len(grid), 3), np.nan), np.full((len(grid), 3), np.nan)
        force[v], torque[v] = cal_mod.compensate_wrench(
            raw[v], pose.quaternion[v], cal, cal_mod.sensor_pose(session, "ft_sensor")
        )
    if "handle_accel" in streams:
        a = streams["handle_accel"]
        raw = lowpass_resample(a["t"].to_numpy(), table_columns(a, ACCEL_COLUMNS), grid, preprocessing.PARAMETERS.accel_cutoff_hz)
        accel = np.full((len(grid), 3), np.nan)
        accel[v] = cal_mod.compensate_accel(raw[v], pose.quaternion[v], cal, cal_mod.sensor_pose(session, "accelerometer"))
    return HandleSignals(
        trial_id=trial_id,
        rate_hz=float(rate_hz),
        t=grid,
        position=pose.position,
        quaternion=pose.quaternion,
        velocity=pose.velocity,
        angular_velocity=pose.angular_velocity,
        acceleration=accel,
        force=force,
        torque=torque,
        valid=v,
    )


def handle_signals(ctx_or_session: Any, trial_id: str, rate_hz: float | None = None) -> HandleSignals:
    """The calibrated handle signals of a trial on a uniform grid at ``rate_hz`` (default ``rate_hz`` parameter; spec §7.5).

    Grid: from the latest first sample to the earliest last sample of the trial's handle_pose,
    handle_wrench and handle_accel streams (those present). Raw streams are low-passed (§7.2), resampled
    and calibrated with the session's handle calibration (§6.4–6.6); motion capture as in §7.4.
    Cached on a ComputeContext under ``("handle_signals", trial_id, rate_hz)``.
    """
    rate = preprocessing.PARAMETERS.rate_hz if rate_hz is None else float(rate_hz)
    session = session_of(ctx_or_session)

    def build() -> HandleSignals:
        cal = None
        if session.stream(trial_id, "handle_wrench") is not None or session.stream(trial_id, "handle_accel") is not None:
            cal = cal_mod.handle_calibration(ctx_or_session)
        return build_handle_signals(ctx_or_session, trial_id, rate, cal)

    return cached(ctx_or_session, ("handle_signals", trial_id, rate), build)


@dataclass
class NativeAccel:
    """Handle acceleration at the accelerometer's own samples (spec §7.6)."""

    t: np.ndarray
    acceleration: np.ndarray  # world frame, bias and gravity removed, unfiltered; NaN where not valid
    sensor: np.ndarray  # accelerometer frame, bias removed only (gravity still in), never NaN
    valid: np.ndarray
    rate_hz: float


def handle_accel_native(ctx_or_session: Any, trial_id: str) -> NativeAccel:
    """Unfiltered handle acceleration at its native rate for vibration analysis (spec §7.6).

    ``sensor`` is the raw reading minus the accelerometer bias in its own frame (always available);
    ``acceleration`` is that rotated to W with gravity removed, using the orientation slerped from
    motion capture (§7.4), NaN where motion capture is unusable or absent. Cached on a context.
    """

    def build() -> NativeAccel:
        session = session_of(ctx_or_session)
        a = session.read(trial_id, "handle_accel")
        t = a["t"].to_numpy()
        cal = cal_mod.handle_calibration(ctx_or_session)
        reading = table_columns(a, ACCEL_COLUMNS)
        sensor = reading - cal.accel_bias_m_per_s2
        world = np.full_like(sensor, np.nan)
        valid = np.zeros(len(t), bool)
        if session.stream(trial_id, "handle_pose") is not None:
            q, valid = orientation_at(mocap_track(ctx_or_session, trial_id), t)
            world[valid] = cal_mod.compensate_accel(reading[valid], q[valid], cal, cal_mod.sensor_pose(session, "accelerometer"))
        return NativeAccel(t=t, acceleration=world, sensor=sensor, valid=valid, rate_hz=nominal_rate(t))

    return cached(ctx_or_session, ("handle_accel_native", trial_id), build)
