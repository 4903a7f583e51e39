"""The Haptify session format: session.json, device, rig, trials and streams (spec chapter 2).

These pydantic models are the source from which ``schemas/<v>/session.schema.json``,
``device.schema.json`` and ``rig.schema.json`` are generated (``python -m haptify_tools.gen_schemas``);
a test fails when the committed schemas are stale. Units are SI throughout (spec §1.1); a field
whose unit is not obvious carries it in its name (``rate_hz``, ``mass_kg``).
"""

from __future__ import annotations

import re
from typing import Annotated, Any, Literal, Union

import numpy as np
from pydantic import BaseModel, ConfigDict, Field

from haptify import schemas
from haptify.versions import SPEC_VERSION

Id = Annotated[
    str,
    Field(
        pattern=r"^[A-Za-z0-9][A-Za-z0-9._-]{0,63}$",
        description="An identifier: letters, digits, '.', '_' or '-', at most 64 characters.",
    ),
]
Vec3 = Annotated[list[float], Field(min_length=3, max_length=3, description="A 3-vector in SI units.")]
Quat = Annotated[
    list[float],
    Field(
        min_length=4,
        max_length=4,
        description="A unit quaternion, scalar first [w, x, y, z], rotating the body frame to the parent frame.",
    ),
]

PROTOCOLS: tuple[str, ...] = tuple(schemas.load("protocols.json")["protocols"])
STREAM_KINDS: tuple[str, ...] = tuple(schemas.load("stream-kinds.json")["kinds"])

# Limits of the spec's size table (§3.5): declared sizes beyond these are absurd (E113).
MAX_ROWS = 500_000_000
MAX_RATE_HZ = 1_000_000.0


class _Strict(BaseModel):
    model_config = ConfigDict(extra="forbid")


class Pose(_Strict):
    """A rigid transform (spec §1.3): ``position`` (m) of the child origin in the parent and ``quaternion`` (wxyz) child → parent."""

    position: Vec3
    quaternion: Quat


# --- device (spec §2.3) -------------------------------------------------------------------------


class LinearLimit(_Strict):
    """A joint limit ``constant + Σ coefficients[q_k] · q_k`` in rad, keyed by earlier joint names (``"q2"``) (spec §2.3)."""

    constant: float = Field(description="Offset in rad.")
    coefficients: dict[Annotated[str, Field(pattern=r"^q[1-9]$")], float] = Field(
        default_factory=dict, description='Dimensionless slope per other joint, e.g. {"q2": -0.85}.'
    )


class DHJoint(_Strict):
    """One revolute joint of a standard (distal) Denavit–Hartenberg chain: Rot_z(θ+θ0)·Trans_z(d)·Trans_x(a)·Rot_x(α); a, d in m, α, θ0 in rad (spec §2.3)."""

    name: Annotated[str, Field(pattern=r"^q[1-9]$")]
    a: float = Field(description="Link length a_i in m.")
    alpha: float = Field(description="Link twist α_i in rad.")
    d: float = Field(description="Link offset d_i in m.")
    theta_offset: float = Field(0.0, description="Constant added to the joint variable, rad.")
    lower: LinearLimit
    upper: LinearLimit


class Kinematics(_Strict):
    """The device's equivalent serial chain: standard DH joints (m, rad) after a base pose in the device frame (spec §2.3)."""

    convention: Literal["dh_standard"] = "dh_standard"
    joints: list[DHJoint] = Field(min_length=1, max_length=9)
    base: Pose = Field(description="Pose of the DH base frame (joint 1 axis) in the device frame.")


class Gimbal(_Strict):
    """The passive wrist: its rotational DOF and the gimbal-centre-to-stylus-tip distance in m (spec §2.3)."""

    dof: int = Field(ge=0, le=3, description="Passive rotational DOF at the end of the arm.")
    tip_offset_m: float = Field(0.0, ge=0, description="Distance from gimbal centre to stylus tip along the stylus axis, m.")


class Datasheet(_Strict):
    """Manufacturer figures in SI units (m, N, N/m, kg); any may be absent (spec §2.3)."""

    workspace_box_m: Vec3 | None = None
    peak_force_N: float | None = None
    continuous_force_N: float | None = None
    stiffness_N_per_m: float | None = None
    friction_N: float | None = None
    mass_kg: float | None = None
    source: str | None = None


class Device(_Strict):
    """A grounded force-feedback device (spec §2.3)."""

    manufacturer: str
    model: str
    serial: str | None = None
    dof: int = Field(ge=1, le=12, description="Actuated plus passive DOF.")
    mechanism: Literal["serial", "hybrid", "parallel", "other"]
    kinematics: Kinematics | None = None
    gimbal: Gimbal | None = None
    datasheet: Datasheet = Field(default_factory=Datasheet)


class DeviceRef(_Strict):
    """A reference to the device description kept in a separate ``device.json`` in the session folder (spec §2.1, §2.3)."""

    file: str = Field(description="Relative path of a device.json inside the session folder.")


# --- rig (spec §2.4) ----------------------------------------------------------------------------


class SensorRange(_Strict):
    """Symmetric measuring range per axis: ``|reading| ≤ range`` in N, N·m or m/s² (spec §2.4)."""

    force_N: Vec3 | None = None
    torque_Nm: Vec3 | None = None
    accel_m_per_s2: Vec3 | None = None


class CornerSensor(_Strict):
    """One of the force plate's four corner 6-axis sensors and the pose of its frame in W (spec §2.4, §1.2)."""

    id: Literal["c1", "c2", "c3", "c4"]
    pose: Pose = Field(description="Sensor frame in the world frame W.")


class ForcePlate(_Strict):
    """The force plate: its size in m (x, y), its four corner sensors and their optional ranges (spec §2.4)."""

    size_m: Annotated[list[float], Field(min_length=2, max_length=2)]
    corners: list[CornerSensor] = Field(min_length=4, max_length=4)
    corner_range: SensorRange | None = None


class HandleSensor(_Strict):
    """A sensor on the handle (F/T sensor or accelerometer): its frame's pose in the handle body frame H (spec §2.4)."""

    pose: Pose = Field(description="Sensor frame in the handle body frame (the frame of handle_pose).")
    range: SensorRange | None = None
    model: str | None = None


class Handle(_Strict):
    """The sensing end-effector: a 6-axis F/T sensor and an accelerometer, both required (spec §2.4)."""

    ft_sensor: HandleSensor
    accelerometer: HandleSensor


class RigidBody(_Strict):
    """A motion-capture rigid body: the device link it is attached to and its marker labels (spec §2.4)."""

    name: Id = Field(description="The link this rigid body is attached to, e.g. 'link2' or 'handle'.")
    markers: list[Id] = Field(min_length=1)


class MotionCapture(_Strict):
    """The motion-capture system: frame rate in Hz, marker labels and rigid bodies (spec §2.4)."""

    system: str | None = None
    rate_hz: float = Field(gt=0, le=MAX_RATE_HZ)
    rigid_bodies: list[RigidBody] = Field(default_factory=list)
    markers: list[Id] = Field(default_factory=list, description="Every marker label the rig uses.")


class Rig(_Strict):
    """The measuring rig (spec §2.4)."""

    name: str | None = None
    force_plate: ForcePlate | None = None
    handle: Handle | None = None
    motion_capture: MotionCapture | None = None


# --- calibration records (spec §2.8) -------------------------------------------------------------


class HandleGravityCalibration(_Strict):
    """Parameters of paper eqs. 1–3, in the sensor frames."""

    kind: Literal["handle_gravity"] = "handle_gravity"
    id: Id
    source_trial: Id | None = None
    force_bias_N: Vec3
    connector_mass_kg: float = Field(ge=0)
    connector_com_m: Vec3
    torque_bias_Nm: Vec3
    accel_bias_m_per_s2: Vec3
    gravity_m_per_s2: float = Field(gt=0)


class PlateBiasCalibration(_Strict):
    """Calibration record ``plate_bias``: the mean of the 24 plate_wrench columns at rest, N and N·m (spec §2.8)."""

    kind: Literal["plate_bias"] = "plate_bias"
    id: Id
    source_trial: Id | None = None
    bias: Annotated[
        list[float], Field(min_length=24, max_length=24, description="Mean of every plate_wrench column (c1_fx … c4_tz) at rest.")
    ]


class ClockOffset(_Strict):
    """Calibration record ``clock_offset``: add ``offset_s`` (s) to one stream's t to put it on the session clock (spec §2.8)."""

    kind: Literal["clock_offset"] = "clock_offset"
    id: Id
    stream_file: str = Field(description="The stream whose time column is shifted.")
    offset_s: float = Field(description="Add this to the stream's t to put it on the session clock.")


Calibration = Annotated[Union[HandleGravityCalibration, PlateBiasCalibration, ClockOffset], Field(discriminator="kind")]


# --- trials and streams (spec §2.5–2.7) ----------------------------------------------------------


class Column(_Strict):
    """One column of a stream: its name and unit (``t`` in s first) (spec §2.6)."""

    name: str
    unit: str


class Stream(_Strict):
    """One recorded table of samples: kind, file, format, nominal rate in Hz, frame, columns, rows, checksum (spec §2.6)."""

    kind: Literal[STREAM_KINDS]  # type: ignore[valid-type]
    file: str = Field(description="Relative path inside the session folder.")
    format: Literal["parquet", "csv"]
    rate_hz: float = Field(gt=0, le=MAX_RATE_HZ, description="Nominal sample rate, Hz.")
    frame: str
    columns: list[Column] = Field(min_length=2, description="'t' first, then the kind's columns in order.")
    rows: int = Field(ge=0, le=MAX_ROWS)
    sha256: str = Field(pattern=r"^[0-9a-f]{64}$")
    entities: list[Id] | None = Field(None, description="Markers (markers) or links (link_poses) in column order.")


class Rendering(_Strict):
    """What the rendering software was asked to display in an active trial (spec §2.5)."""

    surface_point_m: Vec3 = Field(description="A point of the virtual plane, world frame.")
    surface_normal: Vec3 = Field(description="Unit outward normal of the plane, world frame.")
    stiffness_N_per_m: float = Field(gt=0)
    static_friction: float = Field(0.0, ge=0)
    dynamic_friction: float = Field(0.0, ge=0)
    software: str | None = None
    loop_rate_hz: float | None = Field(None, gt=0)


class Trial(_Strict):
    """One recorded trial: its protocol, repetition, powered state, rendering and streams (spec §2.5)."""

    id: Id
    protocol: Literal[PROTOCOLS]  # type: ignore[valid-type]
    label: str | None = None
    repetition: int = Field(1, ge=1)
    powered: bool
    rendering: Rendering | None = None
    notes: str | None = None
    streams: list[Stream]


class Party(_Strict):
    """The lab or the examiner, named by a pseudonymous id (spec §2.1, §2.2)."""

    id: Id = Field(description="A pseudonymous id, never a person's name.")


class Session(_Strict):
    """The manifest of a session folder: ``session.json`` (spec §2.1)."""

    spec_version: Literal[SPEC_VERSION]  # type: ignore[valid-type]
    session_id: Id
    date: str = Field(
        pattern=r"^\d{4}-(0[1-9]|1[0-2])-(0[1-9]|[12]\d|3[01])$", description="ISO date of the recording (YYYY-MM-DD)."
    )
    lab: Party
    examiner: Party
    device: Union[Device, DeviceRef]
    device_placement: Pose = Field(description="The device frame in the world frame W.")
    rig: Rig
    calibration: list[Calibration] = Field(default_factory=list)
    trials: list[Trial] = Field(min_length=1)
    recorder: str | None = Field(None, description="Software that wrote the session, with version.")


def kind_table(kind: str) -> dict[str, Any]:
    """The row of the stream-kind table (``stream-kinds.json``) for ``kind``."""
    row: dict[str, Any] = schemas.load("stream-kinds.json")["kinds"][kind]
    return row


#: Columns whose values come from a closed set (spec §2.6 kind table): the sync trigger is 0 or 1 (E214).
ALLOWED_VALUES: dict[tuple[str, str], tuple[float, ...]] = {("sync", "trigger"): (0.0, 1.0)}


def values_outside_set(kind: str, column: str, values: np.ndarray) -> tuple[np.ndarray, str] | None:
    """For a column with a closed value set (:data:`ALLOWED_VALUES`, E214): the mask of finite values outside
    it and the set in words ("0 or 1"); None for any other column. NaN is judged elsewhere (E204)."""
    allowed = ALLOWED_VALUES.get((kind, column))
    if allowed is None:
        return None
    values = np.asarray(values, dtype=float)
    return np.isfinite(values) & ~np.isin(values, allowed), " or ".join(f"{a:g}" for a in allowed)


def expected_columns(kind: str, entities: list[str] | None = None, present: list[str] | None = None) -> list[tuple[str, str]]:
    """The ``(name, unit)`` columns a stream of ``kind`` must have, time column first (spec §2.6).

    ``entities`` expands per-entity kinds (markers, link_poses); ``present`` lets the optional
    columns of a kind (device_joint_angles' q4–q6) count when a stream has them.
    """
    spec = kind_table(kind)
    time = schemas.load("stream-kinds.json")["time_column"]
    cols = [(time["name"], time["unit"])]
    if "entity_columns" in spec:
        for ent in entities or []:
            cols += [(f"{ent}_{c['name']}", c["unit"]) for c in spec["entity_columns"]]
    else:
        cols += [(c["name"], c["unit"]) for c in spec["columns"]]
        present_set = set(present or [])
        cols += [(c["name"], c["unit"]) for c in spec.get("optional_columns", []) if c["name"] in present_set]
    return cols


def quaternion_groups(kind: str, entities: list[str] | None = None) -> list[list[str]]:
    """Column quadruples (w, x, y, z) that hold unit quaternions in a stream of ``kind``."""
    spec = kind_table(kind)
    groups = [list(g) for g in spec.get("quaternions", [])]
    if kind == "link_poses":
        groups += [[f"{e}_q{c}" for c in "wxyz"] for e in entities or []]
    return groups


def default_stream_file(trial_id: str, kind: str, fmt: str = "parquet") -> str:
    """The conventional relative path of a stream file: ``trials/<trial>/<kind>.<ext>``."""
    return f"trials/{trial_id}/{kind}.{'parquet' if fmt == 'parquet' else 'csv'}"


def is_safe_relative_path(path: str) -> bool:
    """True when ``path`` is relative, uses '/' and never climbs out ('..') — spec §3.3."""
    if not path or path.startswith(("/", "\\")) or re.match(r"^[A-Za-z]:", path) or "\\" in path:
        return False
    return all(part not in ("", ".", "..") for part in path.split("/"))
