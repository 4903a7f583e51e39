"""The device twin file: a versioned model of a grounded force-feedback device (design §4).

A twin file is a superset of the standard device description (:class:`haptify.formats.session_format.Device`,
spec §2.3): ``device`` is the NOMINAL description that goes into simulated sessions, and the other
sections say how the simulated device really behaves. Every physical effect is a separate component
with named parameters and an ``enabled`` switch; effects are addressed by stable ids shared with the
discrepancy workflow (:data:`EFFECT_IDS`).

Conventions (SI units; spec chapter 1):

- Device frame D: the frame the standard's ``device.kinematics.base`` pose is given in; ``placement``
  is D's pose in the world frame W (z up, origin at the centre of the force plate's top surface).
- Link frames are standard (distal) Denavit–Hartenberg frames: link *i*'s frame sits on joint *i+1*'s
  axis with x along the link, so the centre of mass of a straight link of length ``a`` lies near
  ``[-a/2, 0, 0]`` in its own frame.
- Drive axes: each joint's motor drives a *drive coordinate* ``θ = coupling · q`` (the Phantom-style
  hybrid arm drives the absolute angle of the forearm, so its third row is ``[0, 1, 1]``). Friction,
  rotor inertia, saturation, backlash and cable elasticity are expressed per drive axis at the capstan
  OUTPUT (link side): a torque in N·m, an angle in rad. A rotor of inertia ``J_r`` behind a capstan of
  ratio ``n`` appears there as ``n²·J_r``.
- The gimbal body (stylus and distal gimbal parts) moves with the handle; its mass, centre of mass and
  inertia are given in the handle frame (the frame of the standard's ``handle_pose``).
"""

from __future__ import annotations

import copy
import json
from pathlib import Path
from typing import Annotated, Any, Final, Literal, Union

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, ValidationError, model_validator

from haptify.codes import Code
from haptify.errors import fail
from haptify.formats.conventions import STANDARD_GRAVITY
from haptify.formats.session_format import Device, Pose, Vec3

TWIN_FORMAT: Final = "haptify-twin"
TWIN_VERSION: Final = "1.0"
PRESET_DIR = Path(__file__).resolve().parent / "presets"
PRESETS: tuple[str, ...] = ("touch", "touch-x")

#: Every effect id, in the order the discrepancy workflow lists them (TWIN.md, Effects).
EFFECT_IDS: tuple[str, ...] = (
    "gravity",
    "inertia",
    "friction.coulomb",
    "friction.viscous",
    "friction.stribeck",
    "drive.series_elasticity",
    "drive.torque_saturation",
    "drive.force_cutoff",
    "drive.backlash",
    "kinematics.base_collision",
    "kinematics.link_length",
    "sensor.bias",
    "handle.connector_mass",
    "vibration.device",
)
#: Effects consumed by the virtual rig (they live in the twin file's ``rig`` section).
RIG_EFFECT_IDS: tuple[str, ...] = ("sensor.bias", "handle.connector_mass")

PerJoint = Annotated[
    list[float], Field(min_length=1, max_length=9, description="One value per arm joint / drive axis, in joint order.")
]


class _Strict(BaseModel):
    model_config = ConfigDict(extra="forbid", populate_by_name=True, validate_assignment=True)


class Effect(_Strict):
    """Common part of every twin effect: the switch and where its numbers come from (twin/TWIN.md, Effects)."""

    enabled: bool = Field(default=True, description="False switches the effect off (as if the device did not have it).")
    description: str | None = Field(default=None, description="What the effect models, in one sentence.")
    sources: dict[str, str] = Field(default_factory=dict, description="Parameter name -> where its value comes from.")


# --- dynamics effects ---------------------------------------------------------------------------


class GravityEffect(Effect):
    """Effect ``gravity``: weight of every moving part (links and gimbal body) in the world's uniform field, −z, m/s² (TWIN.md, Effects)."""

    g_m_per_s2: float = Field(STANDARD_GRAVITY, gt=0, description="Gravitational acceleration, m/s².")


class InertiaEffect(Effect):
    """Effect ``inertia``: inertial forces of the links, the gimbal body and the motor rotors (reflected through the capstans), kg·m² (TWIN.md, Effects)."""

    rotor_inertia_kg_m2: PerJoint = Field(description="Rotor (plus capstan drum) inertia per motor, on the motor shaft, kg·m².")


class CoulombFriction(Effect):
    """Effect ``friction.coulomb`` (TWIN.md, Effects), torques in N·m, speeds in rad/s.

    ``τ = −τ_c·(1 + r·sin(2π·c·θ))·tanh(ω/ω_s)`` per drive axis (a smooth zero crossing; the level may
    ripple along the drive angle θ), and ``−τ_g·tanh(ω/ω_s)`` at the gimbal joints.
    """

    torque_Nm: PerJoint = Field(description="Coulomb friction torque per drive axis at the capstan output, N·m.")
    zero_crossing_velocity_rad_per_s: float = Field(gt=0, description="ω_s of the tanh zero crossing, rad/s.")
    gimbal_torque_Nm: Vec3 = Field(
        default_factory=lambda: [0.0, 0.0, 0.0], description="Coulomb torque of the three gimbal joints, N·m."
    )
    ripple_fraction: float = Field(
        default=0.0,
        ge=0,
        le=1,
        description="Relative variation of the drive Coulomb torque along the drive angle (cable winding on the capstan drum, motor brushes): τ_c·(1 + r·sin(2π·c·θ)).",
    )
    ripple_cycles_per_rad: float = Field(
        default=10.0, gt=0, description="c: ripple cycles per radian of drive angle (capstan output side)."
    )


class ViscousFriction(Effect):
    """Effect ``friction.viscous``: ``τ = −b · ω`` per drive axis and gimbal joint, b in N·m·s/rad (TWIN.md, Effects)."""

    damping_Nms_per_rad: PerJoint = Field(description="Viscous coefficient per drive axis, N·m·s/rad.")
    gimbal_damping_Nms_per_rad: Vec3 = Field(
        default_factory=lambda: [0.0, 0.0, 0.0], description="Viscous coefficient of the gimbal joints, N·m·s/rad."
    )


class StribeckFriction(Effect):
    """Effect ``friction.stribeck``: extra friction near zero speed, ``τ = −Δτ_s · exp(−(ω/ω_st)²) · tanh(ω/ω_s)``; N·m, rad/s (TWIN.md, Effects)."""

    excess_torque_Nm: PerJoint = Field(description="Breakaway torque minus Coulomb torque per drive axis, N·m.")
    stribeck_velocity_rad_per_s: float = Field(gt=0, description="ω_st: speed at which the excess has fallen to 1/e, rad/s.")
    zero_crossing_velocity_rad_per_s: float = Field(gt=0, description="ω_s of the tanh zero crossing, rad/s.")


class SeriesElasticity(Effect):
    """Effect ``drive.series_elasticity`` (TWIN.md, Effects): cable drive compliance between motor (encoder side) and
    link, ``τ = k·(θ_motor − θ_link) + c·(θ̇_motor − θ̇_link)`` with k in N·m/rad, c in N·m·s/rad.

    When disabled the cable is rigid (the motor angle equals the link-side drive angle).
    """

    stiffness_Nm_per_rad: PerJoint = Field(description="Cable stiffness per drive axis at the capstan output, N·m/rad.")
    damping_Nms_per_rad: PerJoint = Field(description="Cable (and motor) damping per drive axis, N·m·s/rad.")


class TorqueSaturation(Effect):
    """Effect ``drive.torque_saturation``: motor torque limit per drive axis in N·m (amplifier current limit × torque constant × capstan ratio); the Touch's force plateau, paper §VI-F (TWIN.md, Effects)."""

    max_torque_Nm: PerJoint = Field(description="Largest torque per drive axis at the capstan output, N·m.")


class ForceCutoff(Effect):
    """Effect ``drive.force_cutoff`` (TWIN.md, Effects): when the commanded force magnitude exceeds ``trip_force_N`` (N)
    the drive outputs zero torque until the commanded force has fallen below ``rearm_force_N`` (N) — the Touch X's
    sudden drop, paper §VI-F.
    """

    trip_force_N: float = Field(gt=0, description="Commanded force magnitude that trips the cut-off, N.")
    rearm_force_N: float = Field(ge=0, description="Commanded force magnitude below which output resumes, N.")


class Backlash(Effect):
    """Effect ``drive.backlash``: dead band in the cable/capstan, no torque is transmitted within ``±width/2`` (rad) of the rest deflection (TWIN.md, Effects)."""

    width_rad: PerJoint = Field(description="Total play per drive axis at the capstan output, rad.")


# --- kinematic effects --------------------------------------------------------------------------


class Box(_Strict):
    """A box primitive of ``kinematics.base_collision`` in the device frame: centre and half extents in m, orientation quaternion wxyz (TWIN.md, Effects)."""

    shape: Literal["box"] = "box"
    name: str
    center_m: Vec3
    half_extents_m: Vec3
    quaternion: Annotated[list[float], Field(min_length=4, max_length=4)] = Field(default_factory=lambda: [1.0, 0.0, 0.0, 0.0])


class Cylinder(_Strict):
    """A cylinder primitive of ``kinematics.base_collision`` with a vertical (device z) axis: centre of its axis segment, radius, half height, all m (TWIN.md, Effects)."""

    shape: Literal["cylinder"] = "cylinder"
    name: str
    center_m: Vec3
    radius_m: float = Field(gt=0)
    half_height_m: float = Field(gt=0)


class Sphere(_Strict):
    """A sphere primitive of ``kinematics.base_collision`` in the device frame: centre and radius in m (TWIN.md, Effects)."""

    shape: Literal["sphere"] = "sphere"
    name: str
    center_m: Vec3
    radius_m: float = Field(gt=0)


class HalfSpace(_Strict):
    """A half-space primitive of ``kinematics.base_collision``: everything on the ``normal`` side of the plane through ``point_m`` (m, device frame) is solid, e.g. the table: normal −z (TWIN.md, Effects)."""

    shape: Literal["half_space"] = "half_space"
    name: str
    point_m: Vec3
    normal: Vec3


Primitive = Annotated[Union[Box, Cylinder, Sphere, HalfSpace], Field(discriminator="shape")]


class BaseCollision(Effect):
    """Effect ``kinematics.base_collision`` (TWIN.md, Effects): the base and the table as solid primitives (device
    frame); the end-effector, a sphere of radius ``clearance_m`` (m) around the gimbal centre, cannot enter them (the
    Touch's missing lower lobe, paper §VI-A, Fig. 5).
    """

    primitives: list[Primitive] = Field(default_factory=list)
    clearance_m: float = Field(
        default=0.0, ge=0, description="Radius of the end-effector's collision sphere around the gimbal centre, m."
    )


class LinkLength(Effect):
    """Effect ``kinematics.link_length``: true DH lengths differ from the nominal ones, ``a_true = a + delta_a``, ``d_true = d + delta_d``, in m (TWIN.md, Effects)."""

    delta_a_m: PerJoint
    delta_d_m: PerJoint


# --- vibration ----------------------------------------------------------------------------------


class BroadbandSource(_Strict):
    """A broadband source of ``vibration.device``: band-limited noise whose RMS (m/s²) grows with handle speed, ``rms(v) = rms_ref · (v / v_ref)^p``; band in Hz (TWIN.md, Effects)."""

    rms_at_ref_speed_m_per_s2: float = Field(ge=0)
    band_hz: Annotated[list[float], Field(min_length=2, max_length=2, description="Pass band [low, high], Hz.")]
    axis_weights: Vec3 = Field(default_factory=lambda: [1.0, 1.0, 1.0], description="Relative RMS per world axis.")


class ResonantSource(_Strict):
    """A resonant source of ``vibration.device``: a lightly damped mode (frequency in Hz, Q dimensionless) driven by speed-modulated noise, RMS in m/s² (TWIN.md, Effects)."""

    frequency_hz: float = Field(gt=0)
    q_factor: float = Field(gt=0.5)
    rms_at_ref_speed_m_per_s2: float = Field(ge=0)
    axis_weights: Vec3 = Field(default_factory=lambda: [1.0, 1.0, 1.0])


class DeviceVibration(Effect):
    """Effect ``vibration.device``: parasitic acceleration the device adds at the handle (bearings, cable, backlash), world frame, m/s² (TWIN.md, Effects)."""

    ref_speed_m_per_s: float = Field(gt=0, description="v_ref of the speed law, m/s.")
    speed_exponent: float = Field(ge=0, description="p of the speed law.")
    idle_fraction: float = Field(default=0.0, ge=0, description="RMS at rest as a fraction of the RMS at v_ref.")
    broadband: list[BroadbandSource] = Field(default_factory=list)
    resonances: list[ResonantSource] = Field(default_factory=list)


class NoiseFloor(_Strict):
    """The rig's own acceleration noise floor (paper §VI-C: 0.0332 m/s² RMS, centroid 108.25 Hz with no device).

    Band-limited noise on EACH world axis: RMS ``low_rms`` in ``low_band_hz`` plus RMS ``high_rms`` in
    ``high_band_hz`` (the mix sets the centroid; the three-axis RMS is √3 times the per-axis RMS). Not an
    effect (it is the instrument, not the device); the virtual rig adds it to every accelerometer sample.
    """

    low_rms_m_per_s2: float = Field(ge=0, description="RMS per axis of the low band, m/s².")
    low_band_hz: Annotated[list[float], Field(min_length=2, max_length=2)]
    high_rms_m_per_s2: float = Field(ge=0, description="RMS per axis of the high band, m/s².")
    high_band_hz: Annotated[list[float], Field(min_length=2, max_length=2)]
    sources: dict[str, str] = Field(default_factory=dict)


# --- rig effects (behaviour implemented by the virtual rig) --------------------------------------


class SensorBias(Effect):
    """Rig effect ``sensor.bias``: constant offsets of the raw sensors in their own frames, N, N·m, m/s² (the calibration must remove them) (TWIN.md, Effects)."""

    handle_force_N: Vec3 = Field(default_factory=lambda: [0.0, 0.0, 0.0], description="F/T force bias, sensor frame, N.")
    handle_torque_Nm: Vec3 = Field(default_factory=lambda: [0.0, 0.0, 0.0], description="F/T torque bias, sensor frame, N·m.")
    accel_m_per_s2: Vec3 = Field(default_factory=lambda: [0.0, 0.0, 0.0], description="Accelerometer bias, sensor frame, m/s².")
    plate_corner_force_N: Vec3 = Field(
        default_factory=lambda: [0.0, 0.0, 0.0], description="Force bias added to each plate corner sensor, its frame, N."
    )


class ConnectorMass(Effect):
    """The sensing handle's connector between the F/T sensor and the device (paper eqs. 1–3)."""

    mass_kg: float = Field(ge=0)
    com_m: Vec3 = Field(description="Centre of mass in the F/T sensor frame, m.")


class RigTwin(_Strict):
    """Rig-side parts of the twin: the two rig effects and the accelerometer noise floor (TWIN.md, section ``rig``)."""

    sensor_bias: SensorBias = Field(alias="sensor.bias")
    connector_mass: ConnectorMass = Field(alias="handle.connector_mass")
    accel_floor: NoiseFloor


class Effects(_Strict):
    """The device effects, keyed by effect id (TWIN.md, Effects)."""

    gravity: GravityEffect
    inertia: InertiaEffect
    friction_coulomb: CoulombFriction = Field(alias="friction.coulomb")
    friction_viscous: ViscousFriction = Field(alias="friction.viscous")
    friction_stribeck: StribeckFriction = Field(alias="friction.stribeck")
    drive_series_elasticity: SeriesElasticity = Field(alias="drive.series_elasticity")
    drive_torque_saturation: TorqueSaturation = Field(alias="drive.torque_saturation")
    drive_force_cutoff: ForceCutoff = Field(alias="drive.force_cutoff")
    drive_backlash: Backlash = Field(alias="drive.backlash")
    kinematics_base_collision: BaseCollision = Field(alias="kinematics.base_collision")
    kinematics_link_length: LinkLength = Field(alias="kinematics.link_length")
    vibration_device: DeviceVibration = Field(alias="vibration.device")


# --- structure ----------------------------------------------------------------------------------


class LinkDynamics(_Strict):
    """Rigid-body data of one arm link in its own (distal DH) frame: kg, m, kg·m² (TWIN.md, section ``links``)."""

    name: str
    mass_kg: float = Field(ge=0)
    com_m: Vec3 = Field(description="Centre of mass in the link's DH frame, m.")
    inertia_kg_m2: Annotated[
        list[float],
        Field(min_length=6, max_length=6, description="[Ixx, Iyy, Izz, Ixy, Ixz, Iyz] about the COM in link axes, kg·m²."),
    ]
    source: str | None = None


class GimbalBody(_Strict):
    """The parts that turn with the handle (stylus, last gimbal ring), in the handle frame: kg, m, kg·m² (TWIN.md, section ``gimbal_body``)."""

    mass_kg: float = Field(ge=0)
    com_m: Vec3 = Field(description="Centre of mass relative to the gimbal centre, handle frame, m.")
    inertia_kg_m2: Vec3 = Field(description="Principal moments about the COM along the handle axes, kg·m².")
    axes: Literal["zxz", "zyx", "zxy", "xyz", "yzx"] = Field(
        default="zxy", description="Intrinsic rotation sequence of the three gimbal joints relative to the last arm frame."
    )
    alignment: Annotated[list[float], Field(min_length=4, max_length=4)] = Field(
        default_factory=lambda: [1.0, 0.0, 0.0, 0.0],
        description="Handle frame in the last DH frame when every gimbal angle is zero, quaternion wxyz.",
    )
    source: str | None = None


class Drive(_Strict):
    """The transmission: capstan ratios (dimensionless) and the coupling θ = C·q of link-side drive angles, rad (TWIN.md, section ``drive``)."""

    capstan_ratio: PerJoint = Field(description="Motor angle / drive angle per axis (dimensionless).")
    coupling: list[list[float]] = Field(description="Square matrix C: drive angles θ = C · q (rad).")
    torque_constant_Nm_per_A: float | None = Field(default=None, gt=0, description="Motor torque constant, documentation only.")


class BaseBody(_Strict):
    """The static base: mass in kg and centre of mass in m in the device frame (loads the force plate) (TWIN.md, section ``base``)."""

    mass_kg: float = Field(ge=0)
    com_m: Vec3


class TwinFile(_Strict):
    """A device twin (TWIN.md): the nominal device description plus the behaviour of the real device."""

    format: Literal["haptify-twin"] = TWIN_FORMAT
    twin_version: Literal["1.0"] = TWIN_VERSION
    name: str
    description: str | None = None
    device: Device = Field(description="The nominal, standard device description (spec §2.3) written into sessions.")
    placement: Pose = Field(description="Device frame in the world frame W.")
    base: BaseBody
    links: list[LinkDynamics]
    gimbal_body: GimbalBody
    drive: Drive
    effects: Effects
    rig: RigTwin
    sources: dict[str, str] = Field(default_factory=dict, description="Free-form references: key -> citation.")

    @model_validator(mode="after")
    def _sizes(self) -> "TwinFile":
        if self.device.kinematics is None:
            raise ValueError("device.kinematics is required in a twin file")
        n = len(self.device.kinematics.joints)
        if len(self.links) != n:
            raise ValueError(f"links: expected {n} entries (one per joint), found {len(self.links)}")
        per_joint = {
            "drive.capstan_ratio": self.drive.capstan_ratio,
            "inertia.rotor_inertia_kg_m2": self.effects.inertia.rotor_inertia_kg_m2,
            "friction.coulomb.torque_Nm": self.effects.friction_coulomb.torque_Nm,
            "friction.viscous.damping_Nms_per_rad": self.effects.friction_viscous.damping_Nms_per_rad,
            "friction.stribeck.excess_torque_Nm": self.effects.friction_stribeck.excess_torque_Nm,
            "drive.series_elasticity.stiffness_Nm_per_rad": self.effects.drive_series_elasticity.stiffness_Nm_per_rad,
            "drive.series_elasticity.damping_Nms_per_rad": self.effects.drive_series_elasticity.damping_Nms_per_rad,
            "drive.torque_saturation.max_torque_Nm": self.effects.drive_torque_saturation.max_torque_Nm,
            "drive.backlash.width_rad": self.effects.drive_backlash.width_rad,
            "kinematics.link_length.delta_a_m": self.effects.kinematics_link_length.delta_a_m,
            "kinematics.link_length.delta_d_m": self.effects.kinematics_link_length.delta_d_m,
        }
        for key, values in per_joint.items():
            if len(values) != n:
                raise ValueError(f"{key}: expected {n} values (one per joint), found {len(values)}")
        if len(self.drive.coupling) != n or any(len(r) != n for r in self.drive.coupling):
            raise ValueError(f"drive.coupling: expected a {n}×{n} matrix")
        if abs(np.linalg.det(np.asarray(self.drive.coupling))) < 1e-9:
            raise ValueError("drive.coupling must be invertible")
        if self.effects.drive_force_cutoff.rearm_force_N > self.effects.drive_force_cutoff.trip_force_N:
            raise ValueError("drive.force_cutoff: rearm_force_N must not exceed trip_force_N")
        return self

    # convenient access by effect id
    def effect(self, effect_id: str) -> Effect:
        """The component of effect ``effect_id`` (one of :data:`EFFECT_IDS`)."""
        return _effect(self, effect_id)

    def on(self, effect_id: str) -> bool:
        """True when effect ``effect_id`` is enabled."""
        return _effect(self, effect_id).enabled


def _attr(effect_id: str) -> str:
    return effect_id.replace(".", "_")


def _effect(twin: TwinFile, effect_id: str) -> Effect:
    if effect_id not in EFFECT_IDS:
        raise fail(Code.TWIN_UNKNOWN_EFFECT, f"unknown effect id {effect_id!r}", expected=list(EFFECT_IDS), found=effect_id)
    holder = twin.rig if effect_id in RIG_EFFECT_IDS else twin.effects
    name = {"sensor.bias": "sensor_bias", "handle.connector_mass": "connector_mass"}.get(effect_id, _attr(effect_id))
    return getattr(holder, name)


# --- file I/O -----------------------------------------------------------------------------------


def _validation_error(err: ValidationError, file: str | None) -> Exception:
    from haptify.errors import Finding, HaptifyError

    findings = []
    for e in err.errors():
        pointer = "/" + "/".join(str(p) for p in e["loc"])
        findings.append(
            Finding(
                Code.TWIN_FILE_INVALID,
                f"twin file: {e['msg']}",
                file=file,
                pointer=pointer,
                found=e.get("input") if not isinstance(e.get("input"), dict) else None,
            )
        )
    return HaptifyError(*findings)


def twin_from_dict(data: dict, file: str | None = None) -> TwinFile:
    """Validate a twin dictionary; every problem becomes an E802 finding naming its JSON pointer."""
    try:
        return TwinFile.model_validate(data)
    except ValidationError as err:
        raise _validation_error(err, file) from None


def load_twin(path: str | Path) -> TwinFile:
    """Read and validate a twin JSON file (E802 on any problem, E101-style message when unreadable)."""
    path = Path(path)
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise fail(Code.TWIN_FILE_INVALID, f"cannot read twin file: {exc}", file=str(path)) from None
    if not isinstance(data, dict):
        raise fail(Code.TWIN_FILE_INVALID, "a twin file must hold a JSON object", file=str(path), found=type(data).__name__)
    return twin_from_dict(data, file=str(path))


def preset(name: str) -> TwinFile:
    """The preset twin ``touch`` or ``touch-x`` (files in ``presets/``)."""
    if name not in PRESETS:
        raise fail(Code.TWIN_UNKNOWN_EFFECT, f"unknown preset {name!r}", expected=list(PRESETS), found=name)
    return load_twin(PRESET_DIR / f"{name}.json")


def twin_to_dict(twin: TwinFile) -> dict:
    """The JSON-ready dictionary of a twin (effect ids as keys)."""
    return twin.model_dump(mode="json", by_alias=True)


def write_twin(twin: TwinFile, path: str | Path) -> Path:
    """Write a twin file atomically (spec §3.6 style)."""
    from haptify.formats.storage import atomic_write_json

    path = Path(path)
    atomic_write_json(path, twin_to_dict(twin))
    return path


# --- editing (for --disable / --set) -------------------------------------------------------------


def disable(twin: TwinFile, effect_id: str) -> TwinFile:
    """A copy of ``twin`` with effect ``effect_id`` switched off (E801 for an unknown id)."""
    return set_param(twin, f"{effect_id}.enabled", False)


def _parse_value(value: Any) -> Any:
    if isinstance(value, str):
        text = value.strip()
        if text.lower() in ("true", "false"):
            return text.lower() == "true"
        try:
            return json.loads(text)
        except json.JSONDecodeError:
            return text
    return value


def set_param(twin: TwinFile, path: str, value: Any) -> TwinFile:
    """A copy of ``twin`` with one parameter changed: ``set_param(t, "friction.coulomb.torque_Nm", 0.02)``.

    ``path`` is ``<effect id>.<parameter>``; a parameter holding one value per joint accepts either a
    list or one number (applied to every joint), or ``<effect id>.<parameter>[<index>]`` for one entry.
    Values given as strings (from the command line) are parsed as JSON. Paths that do not start with an
    effect id address any other field of the twin file by dotted name (``links.1.mass_kg``).
    Errors: E801 (unknown effect or parameter), E802 (the new value is invalid).
    """
    value = _parse_value(value)
    effect_id = next((e for e in sorted(EFFECT_IDS, key=len, reverse=True) if path.startswith(e + ".")), None)
    data = twin_to_dict(twin)
    if effect_id is not None:
        holder = data["rig"] if effect_id in RIG_EFFECT_IDS else data["effects"]
        keys = [effect_id] + path[len(effect_id) + 1 :].split(".")
    else:
        holder = data
        keys = path.split(".")
    index = None
    if keys[-1].endswith("]") and "[" in keys[-1]:
        name, _, idx = keys[-1][:-1].partition("[")
        keys[-1] = name
        try:
            index = int(idx)
        except ValueError:
            raise fail(Code.TWIN_UNKNOWN_EFFECT, f"bad index in {path!r}", found=path) from None
    node = holder
    for k in keys[:-1]:
        if isinstance(node, list) and k.isdigit() and int(k) < len(node):
            node = node[int(k)]
        elif isinstance(node, dict) and k in node:
            node = node[k]
        else:
            raise fail(
                Code.TWIN_UNKNOWN_EFFECT,
                f"no parameter {path!r} in the twin",
                found=path,
                expected="<effect id>.<parameter>, effect ids: " + ", ".join(EFFECT_IDS),
            )
    last: str | int = keys[-1]
    if isinstance(node, list) and keys[-1].isdigit():
        last = int(keys[-1])
        if last >= len(node):
            raise fail(Code.TWIN_UNKNOWN_EFFECT, f"no parameter {path!r} in the twin", found=path)
    elif not isinstance(node, dict) or last not in node:
        expected = sorted(node) if isinstance(node, dict) else None
        raise fail(Code.TWIN_UNKNOWN_EFFECT, f"no parameter {path!r} in the twin", found=path, expected=expected)
    current = node[last]
    if index is not None:
        if not isinstance(current, list) or not 0 <= index < len(current):
            raise fail(Code.TWIN_UNKNOWN_EFFECT, f"{path!r}: index out of range", found=path)
        current = copy.copy(current)
        current[index] = value
        value = current
    elif (
        isinstance(current, list)
        and isinstance(value, (int, float))
        and not isinstance(value, bool)
        and all(isinstance(v, (int, float)) for v in current)
    ):
        value = [float(value)] * len(current)
    node[last] = value
    return twin_from_dict(data)
