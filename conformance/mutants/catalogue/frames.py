"""Mutants of units, frames, rotations and signs (spec chapter 1) and of the handle calibration (spec chapter
6): millimetres, degrees, quaternion conventions, the force sensor's rotation, gravity and the connector."""

from __future__ import annotations

import dataclasses
import math
from typing import Any, Callable

import numpy as np

from haptify.formats import storage
from haptify.formats.conventions import STANDARD_GRAVITY, quat_conjugate, quat_rotate
from haptify.metrics import free_space
from haptify.processing import calibration
from haptify.processing.caching import session_of
from haptify_mutants.catalogue.model import Make, Mutant, Patch, _post


def _pose_table(transform: Callable[[Any], None], kinds: tuple[str, ...] = ("handle_pose",)) -> Make:
    """``SessionFolder.read`` with ``transform(table)`` applied (in place, on a copy) to streams of ``kinds``."""

    def make(real: Callable) -> Callable:
        def read(self: Any, trial_id: str, kind: str, **kw: Any) -> Any:
            table = real(self, trial_id, kind, **kw)
            if kind in kinds:
                table = table.copy()
                transform(table)
            return table

        return read

    return make


def _millimetres(table: Any) -> None:
    """Motion-capture positions taken for millimetres and divided by 1000."""
    cols = [c for c in table.columns if c in ("px", "py", "pz") or c.endswith(("_x", "_y", "_z"))]
    table[cols] = table[cols] / 1000.0


def _conjugated(table: Any) -> None:
    """Stored quaternions read as world → body (the passive convention)."""
    table[["qx", "qy", "qz"]] = -table[["qx", "qy", "qz"]]


def _scalar_last(table: Any) -> None:
    """The four quaternion columns read as x, y, z, w (scipy / ROS order) instead of w, x, y, z."""
    q = table[["qw", "qx", "qy", "qz"]].to_numpy()
    table[["qw", "qx", "qy", "qz"]] = q[:, [3, 0, 1, 2]]


def _with_calibration(**changes: Callable[[Any], Any]) -> Make:
    """``compensate_wrench``/``compensate_accel`` with calibration fields replaced (``field=lambda cal: value``)."""

    def make(real: Callable) -> Callable:
        def compensate(raw: np.ndarray, q_handle: np.ndarray, cal: Any, pose: Any) -> Any:
            return real(raw, q_handle, dataclasses.replace(cal, **{k: f(cal) for k, f in changes.items()}), pose)

        return compensate

    return make


def _wrench_inverse_rotation(result: tuple, raw: np.ndarray, q_handle: np.ndarray, *_: Any) -> tuple:
    """F_W = R_WHᵀ F_H: the handle orientation applied inverted (world → body)."""
    conj = quat_conjugate(q_handle)
    return tuple(quat_rotate(conj, quat_rotate(conj, v)) for v in result)


def _torque_about_sensor(result: tuple, raw: np.ndarray, q_handle: np.ndarray, cal: Any, pose: Any) -> tuple:
    """The torque left about the sensor origin (the p_S × F_H term of §6.5 omitted)."""
    force, torque = result
    return force, torque - np.cross(quat_rotate(q_handle, np.asarray(pose.position, dtype=float)), force)


def _sensor_rotation_inverted(real: Callable) -> Callable:
    """The F/T sensor's rig quaternion read as the pose of H in S (R_SH) instead of S in H."""

    def compensate_wrench(raw: np.ndarray, q_handle: np.ndarray, cal: Any, pose: Any) -> tuple:
        inverted = pose.model_copy(update={"quaternion": [float(v) for v in quat_conjugate(np.asarray(pose.quaternion))]})
        return real(raw, q_handle, cal, inverted)

    return compensate_wrench


def _accel_in_handle_frame(real: Callable) -> Callable:
    """R_HA (a − b_a) − g: the acceleration never rotated into W."""

    def compensate_accel(raw: np.ndarray, q_handle: np.ndarray, cal: Any, pose: Any) -> np.ndarray:
        identity = np.tile([1.0, 0.0, 0.0, 0.0], (len(np.asarray(q_handle)), 1))
        return real(raw, identity, cal, pose)

    return compensate_accel


def _gravity_added_back(g: Callable[[Any], float]) -> Make:
    """``compensate_accel`` with ``g(cal)`` added to the vertical component of its result."""

    def post(a: np.ndarray, raw: np.ndarray, q_handle: np.ndarray, cal: Any, pose: Any) -> np.ndarray:
        a = np.array(a, copy=True)
        a[:, 2] += g(cal)
        return a

    return _post(post)


def _first_record(real: Callable) -> Callable:
    """The FIRST handle_gravity record in manifest order applies (the last one is the spec's)."""

    def handle_calibration(ctx_or_session: Any) -> Any:
        session = session_of(ctx_or_session)
        records = [c for c in session.manifest.calibration if c.kind == "handle_gravity"]
        return calibration.HandleCalibration.from_record(records[0]) if records else real(ctx_or_session)

    return handle_calibration


MUTANTS: tuple[Mutant, ...] = (
    # units
    Mutant(
        "mm_for_m",
        "1.1",
        "R1.1-1",
        "motion-capture positions are in metres",
        "read as millimetres and divided by 1000",
        (Patch(storage.SessionFolder, "read", _pose_table(_millimetres, ("handle_pose", "markers"))),),
        ("free_space.speed_mean",),
        cheap=True,
    ),
    Mutant(
        "degrees_for_radians",
        "9.4",
        "R9.4-1",
        "angular speed is reported in rad/s",
        "in deg/s under the unit rad/s",
        (Patch(free_space, "_speed_summary", _post(lambda out, *_: {**out, "angular": out["angular"] * 180.0 / math.pi})),),
        ("free_space.angular_speed_mean",),
        cheap=True,
    ),
    # frames, rotations, signs
    Mutant(
        "opposite_force_sign",
        "6.5",
        "R1.5-1",
        "the reported force is the one the device applies to the hand",
        "the force the hand applies to the device",
        (Patch(calibration, "compensate_wrench", _post(lambda r, *_: (-r[0], -r[1]))),),
        ("stiffness.measured", "dynamics.error_vs_distance"),
    ),
    Mutant(
        "inverse_handle_rotation",
        "6.5",
        "R6.5-1",
        "F_W = R_WH F_H with R_WH from the handle quaternion (body → world)",
        "the handle rotation applied inverted (R_WHᵀ)",
        (Patch(calibration, "compensate_wrench", _post(_wrench_inverse_rotation)),),
        ("surface.planar_force_mean", "dynamics.error_vs_distance"),
        cheap=True,
    ),
    Mutant(
        "quaternion_conjugate_convention",
        "1.3",
        "R1.3-1",
        "stored quaternions rotate body → world",
        "read as world → body (passive, conjugated)",
        (Patch(storage.SessionFolder, "read", _pose_table(_conjugated)),),
        ("free_space.force_mean",),
        cheap=True,
    ),
    Mutant(
        "quaternion_scalar_last",
        "1.3",
        "R1.3-1",
        "quaternion columns are w, x, y, z (scalar first)",
        "read as x, y, z, w (scalar last, as scipy and ROS store them)",
        (Patch(storage.SessionFolder, "read", _pose_table(_scalar_last)),),
        ("free_space.force_mean",),
        cheap=True,
    ),
    Mutant(
        "torque_about_sensor_origin",
        "6.5",
        "R6.5-2",
        "the torque is moved to the gimbal centre (+ p_S × F_H)",
        "the torque is left about the F/T sensor's origin",
        (Patch(calibration, "compensate_wrench", _post(_torque_about_sensor)),),
        ("dynamics.torque_rmse",),
    ),
    Mutant(
        "ft_rotation_inverted",
        "1.2",
        "R1.2-1",
        "a rig pose gives the sensor frame in the handle frame (R_HS)",
        "read as the handle frame in the sensor frame (R_SH)",
        (Patch(calibration, "compensate_wrench", _sensor_rotation_inverted),),
        ("free_space.force_mean",),
        cheap=True,
    ),
    Mutant(
        "accel_not_rotated_to_world",
        "6.6",
        "R6.6-1",
        "a_W = R_WH R_HA (a_A − b_a) − (0, 0, g)",
        "the handle rotation R_WH left out (acceleration in the handle frame)",
        (Patch(calibration, "compensate_accel", _accel_in_handle_frame),),
        ("dynamics.error_vs_distance",),
        cheap=True,
    ),
    Mutant(
        "gravity_left_in_acceleration",
        "6.6",
        "R6.6-1",
        "gravity is removed from the handle acceleration",
        "the specific force is reported (gravity left in)",
        (Patch(calibration, "compensate_accel", _gravity_added_back(lambda cal: cal.gravity_m_per_s2)),),
        ("dynamics.error_vs_distance",),
        cheap=True,
    ),
    Mutant(
        "accel_bias_kept",
        "6.6",
        "R6.6-1",
        "the accelerometer bias b_a is subtracted",
        "the bias is left in the acceleration",
        (Patch(calibration, "compensate_accel", _with_calibration(accel_bias_m_per_s2=lambda c: np.zeros(3))),),
        ("dynamics.error_vs_distance",),
        cheap=True,
    ),
    Mutant(
        "accel_gravity_9_81",
        "6.6",
        "R6.6-1",
        "gravity is removed with the accelerometer's own g (the sphere radius)",
        "with a hard-coded 9.81 m/s²",
        (Patch(calibration, "compensate_accel", _gravity_added_back(lambda cal: cal.gravity_m_per_s2 - 9.81)),),
        ("dynamics.error_vs_distance",),
        cheap=True,
    ),
    Mutant(
        "connector_weight_kept",
        "6.5",
        "R6.5-1",
        "the connector's weight m g is removed from the force",
        "only the bias is removed",
        (Patch(calibration, "compensate_wrench", _with_calibration(connector_mass_kg=lambda c: 0.0)),),
        ("free_space.force_mean",),
        cheap=True,
    ),
    Mutant(
        "calibration_first_record",
        "6.4",
        "R6.4-1",
        "the LAST handle_gravity record in manifest order applies",
        "the first one",
        (Patch(calibration, "handle_calibration", _first_record),),
        ("free_space.force_mean",),
        cheap=True,
    ),
    Mutant(
        "connector_weight_at_9_8",
        "6.4",
        "R6.5-1",
        "the connector weight removed is m·g0 (g0 = 9.80665 m/s²)",
        "m·9.8 (the rounded g of textbooks)",
        (
            Patch(
                calibration,
                "compensate_wrench",
                _with_calibration(connector_mass_kg=lambda c: c.connector_mass_kg * 9.8 / STANDARD_GRAVITY),
            ),
        ),
        ("dynamics.error_vs_distance",),
        cheap=True,
    ),
)
