"""Simulate a full benchmarking dossier into ONE standard session, with its ground truth beside it (design §4).

``simulate_dossier(twin, out_dir, options)`` runs the virtual examiner (:mod:`.examiner`) through every
requested protocol and repetition plus the rig's calibration trials, drives the twin's physics
(:mod:`.physics`: passive inverse dynamics or the active rendering loop), turns the true signals into
raw streams with the virtual rig (:mod:`.rig`) and writes:

- ``<out>/session/`` — a standard 1.0 session (spec chapters 2–3) written atomically by
  :class:`haptify.storage.SessionWriter`; nothing in it reveals the truth;
- ``<out>/truth.json`` — every effect's parameters (the whole twin), the rig's noise levels, biases and
  geometry, every trial's examiner parameters and clock offsets;
- ``<out>/truth.npz`` — the true trajectories, joint and gimbal angles and wrenches per trial (1 kHz), the
  connector's inertial force ``m a_c`` (``connector_inertia_W``, which the reported hand force keeps, spec §6.1),
  a perfect accelerometer's reading (``accel_t``, ``accel_A``: the accelerometer's clock and frame).

Everything is a deterministic function of the twin, the options and the seed: each trial draws from
its own generator seeded by ``(seed, crc32(trial id))``, so a trial is identical whichever other
protocols are simulated with it.
"""

from __future__ import annotations

import math
import os
import shutil
import tempfile
import time
import zipfile
import zlib
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Iterator

import numpy as np

from haptify.conventions import matrix_to_quat, pose_apply, quat_to_matrix
from haptify.errors import fail
from haptify.storage import SessionWriter, atomic_write_json
from haptify.versions import PACKAGE_VERSION

from haptify_tools.twin import examiner as ex
from haptify_tools.twin import hand_path, plate_loads
from haptify_tools.twin.reach import reach_from_twin
from haptify_tools.twin import rig as rg
from haptify_tools.twin.kinematics import device_to_world, hand_to_joints, link_transforms, true_kinematics
from haptify_tools.twin.model import TwinFile, twin_to_dict
from haptify_tools.twin.physics import ActiveResult, PassiveResult, device_vibration, simulate_active, simulate_passive

#: Device protocols the examiner performs, in recording order; ``figure_eight`` is protocol ``other``.
DEVICE_PROTOCOLS: tuple[str, ...] = (
    "workspace",
    "free_space",
    "local_dynamic",
    "figure_eight",
    "frictionless_surface",
    "stiffness",
)
#: Rig calibration trials, recorded once before the device trials (paper §III, §V-B, Appendix).
RIG_TRIALS: tuple[str, ...] = (
    "rig.plate_bias",
    "rig.handle_calibration",
    "rig.plate_impact",
    "rig.plate_cop",
    "rig.baseline_vibration",
)
#: Default durations, s. The paper gives ≈140 s for the local dynamic protocol (§V-C); the others are
#: chosen so that a dossier of 3 repetitions records about a quarter of an hour (≈18 min with the rig
#: trials) and the workspace sweep is dense enough (lines ≤ 3 cm apart) for the volume operator.
DEFAULT_DURATIONS: dict[str, float] = {
    "workspace": 75.0,
    "free_space": 40.0,
    "local_dynamic": ex.LOCAL_DYNAMIC_DURATION,
    "figure_eight": 25.0,
    "frictionless_surface": 25.0,
    "stiffness": 30.0,
    "rig.plate_bias": 5.0,
    "rig.handle_calibration": 30.0,
    "rig.plate_impact": 3.0,
    "rig.plate_cop": 0.0,
    "rig.baseline_vibration": 30.0,
}
RENDER_STIFFNESS_N_PER_M = 750.0  # paper §V-D: 0.75 N/mm
TRIAL_GAP_S = 5.0  # idle time between trials on the session clock
SESSION_DATE = "2026-11-22"


@dataclass
class SimulationOptions:
    """What to simulate. ``protocols`` may hold device protocols and rig trial names."""

    protocols: tuple[str, ...] = DEVICE_PROTOCOLS
    reps: int = 3
    seed: int = 0
    rig_trials: bool = True
    durations: dict[str, float] = field(default_factory=dict)
    rig: rg.RigConfig = field(default_factory=rg.RigConfig)
    rate_hz: float = hand_path.DEFAULT_RATE_HZ
    fmt: str = "parquet"
    compact: bool = False  # Parquet: float32 sensor columns, BYTE_STREAM_SPLIT (spec §3.2.1)
    session_id: str | None = None
    lab_id: str = "lab-virtual"  # the manifest's lab.id (a round robin gives every lab its own)
    examiner_id: str = "examiner-virtual"
    examiner_pace: float = 1.0  # the examiner's speeds × pace (free space, surface, presses, figure eight)
    workers: int = 0  # processes simulating trials in parallel; 0 = one per CPU (at most 4)

    def duration(self, name: str) -> float:
        return float(self.durations.get(name, DEFAULT_DURATIONS[name]))


def parse_protocols(text: str) -> tuple[str, ...]:
    """``all`` or a comma-separated list of device protocols / rig trial names (E903 for unknown names).
    Protocols of spec §2.5."""
    if text.strip() == "all":
        return DEVICE_PROTOCOLS
    names = tuple(n.strip() for n in text.split(",") if n.strip())
    bad = [n for n in names if n not in DEVICE_PROTOCOLS + RIG_TRIALS]
    if bad or not names:
        raise fail("E903", f"unknown protocol(s) {bad or text!r}", expected=["all", *DEVICE_PROTOCOLS, *RIG_TRIALS], found=text)
    return names


def name_number(item: str) -> tuple[str, float]:
    """``NAME=NUMBER`` (a command-line assignment) → ``(NAME, NUMBER)``; NaN when there is no ``=`` or the
    value is not a number, for the caller to refuse with its own message."""
    name, sep, value = item.partition("=")
    try:
        number = float(value) if sep else math.nan
    except ValueError:
        number = math.nan
    return name.strip(), number


@contextmanager
def built_in_place(out: Path) -> Iterator[Path]:
    """A fresh folder beside ``out`` to build in; when the block ends normally it replaces ``out`` in one rename,
    otherwise it is removed, so an interrupted run leaves nothing half-written (spec §3.6)."""
    out.parent.mkdir(parents=True, exist_ok=True)
    build = Path(tempfile.mkdtemp(prefix=f".{out.name}.tmp-", dir=out.parent))
    try:
        yield build
        if out.exists():
            shutil.rmtree(out)
        os.replace(build, out)
    except BaseException:
        shutil.rmtree(build, ignore_errors=True)
        raise


def trial_rng(seed: int, trial_id: str) -> tuple[np.random.Generator, np.random.Generator, np.random.Generator]:
    """Three independent generators (examiner, rig, device vibration) for one trial, from ``(seed, crc32(id))``."""
    ss = np.random.SeedSequence([int(seed) & 0xFFFFFFFF, zlib.crc32(trial_id.encode())])
    return tuple(np.random.default_rng(s) for s in ss.spawn(3))  # type: ignore[return-value]


def trial_ft_gain(cfg: rg.RigConfig, seed: int, trial_id: str) -> float:
    """The handle F/T's gain during one trial: ``ft_gain · (1 + δ)``, δ ~ N(0, ``ft_gain_drift_sd``) drawn
    from ``(seed, crc32(trial id), 4)`` (its own generator, so a drift leaves every other draw unchanged)."""
    if cfg.ft_gain_drift_sd <= 0:
        return float(cfg.ft_gain)
    rng = np.random.default_rng(np.random.SeedSequence([int(seed) & 0xFFFFFFFF, zlib.crc32(trial_id.encode()), 4]))
    return float(cfg.ft_gain * (1.0 + rng.normal(0.0, cfg.ft_gain_drift_sd)))


# --- the plan ------------------------------------------------------------------------------------


@dataclass
class PlannedTrial:
    """A planned trial: id, trial name, standard protocol (spec §2.5), repetition, label, start ``t0`` (s)."""

    trial_id: str
    name: str  # device protocol or rig trial name
    protocol: str  # the standard protocol
    repetition: int
    label: str | None = None
    t0: float = 0.0  # start on the session clock, s


def planned_duration(name: str, options: SimulationOptions) -> float:
    """Length (s) of a trial's clock: its configured duration (the COP trial: its placement schedule)."""
    if name == "rig.plate_cop":
        n = len(plate_loads.cop_grid())
        dwell, move = cop_dwell(options), plate_loads.COP_MOVE_S
        return 0.5 + n * (dwell + move) + 0.5
    return options.duration(name)


def cop_dwell(options: SimulationOptions) -> float:
    """Dwell time (s) per weight position of the COP trial (from its configured duration when given)."""
    d = options.duration("rig.plate_cop")
    return plate_loads.COP_DWELL_S if d <= 0 else max(0.3, (d - 1.0) / len(plate_loads.cop_grid()) - plate_loads.COP_MOVE_S)


def plan(options: SimulationOptions) -> list[PlannedTrial]:
    """The trials of the dossier in recording order: rig trials first, then each protocol × repetitions.

    Each trial starts on the session clock at a whole second, ``TRIAL_GAP_S`` after the previous one.
    """
    out: list[PlannedTrial] = []
    rig_names = [n for n in RIG_TRIALS if (options.rig_trials or n in options.protocols)]
    for name in rig_names:
        out.append(PlannedTrial(f"{name}-1", name, name, 1))
    for name in DEVICE_PROTOCOLS:
        if name not in options.protocols:
            continue
        for rep in range(1, options.reps + 1):
            if name == "figure_eight":
                out.append(PlannedTrial(f"figure_eight-{rep}", name, "other", rep, label="figure_eight"))
            else:
                out.append(PlannedTrial(f"{name}-{rep}", name, name, rep))
    now = 0.0
    for p in out:
        p.t0 = now
        now = float(np.ceil(now + planned_duration(p.name, options) + TRIAL_GAP_S))
    return out


# --- simulation of one trial ------------------------------------------------------------------------


def _paced(periods_s: tuple[float, float], pace: float) -> tuple[float, float]:
    """A protocol's first and last period (s) at the examiner's ``pace`` (periods ÷ it)."""
    return periods_s[0] / pace, periods_s[1] / pace


def _no_streams() -> tuple[dict[str, dict[str, np.ndarray]], dict[str, float], dict[str, list[str]], dict[str, float]]:
    """A trial's streams (kind → columns), rates (Hz), entities and clock offsets (s), before any is made."""
    return {}, {}, {}, {}


@dataclass
class TrialOutput:
    """The raw streams of one trial (kind → columns incl. ``t``), its truth and its clock offsets.
    Stream kinds of spec §2.6; offsets in s."""

    planned: PlannedTrial
    powered: bool
    streams: dict[str, dict[str, np.ndarray]]
    rates: dict[str, float]
    entities: dict[str, list[str]]
    rendering: dict | None
    truth: dict
    arrays: dict[str, np.ndarray]
    end_time: float


class DossierSimulator:
    """Simulates the trials of one twin on one virtual rig (see the module docstring)."""

    def __init__(self, twin: TwinFile, options: SimulationOptions) -> None:
        self.twin = twin
        self.opt = options
        self.cfg = options.rig
        self.reach = reach_from_twin(twin)
        self.kin = true_kinematics(twin)
        self.link_names = [lk.name for lk in twin.links]
        self.layout = rg.marker_layout(self.link_names, [j.a for j in self.kin.joints])
        rs = twin.rig
        self.bias_f = np.asarray(rs.sensor_bias.handle_force_N if rs.sensor_bias.enabled else [0.0] * 3, float)
        self.bias_t = np.asarray(rs.sensor_bias.handle_torque_Nm if rs.sensor_bias.enabled else [0.0] * 3, float)
        self.bias_a = np.asarray(rs.sensor_bias.accel_m_per_s2 if rs.sensor_bias.enabled else [0.0] * 3, float)
        self.bias_p = np.asarray(rs.sensor_bias.plate_corner_force_N if rs.sensor_bias.enabled else [0.0] * 3, float)
        self.conn_m = float(rs.connector_mass.mass_kg) if rs.connector_mass.enabled else 0.0
        self.conn_r = np.asarray(rs.connector_mass.com_m, float)
        rig_rng = np.random.default_rng(np.random.SeedSequence([int(options.seed) & 0xFFFFFFFF, zlib.crc32(b"rig")]))
        self.plate_errors = rg.PlateErrors.draw(rig_rng, self.cfg)
        centre = self.reach.centre()
        self.surface: dict[str, Any] = {  # the trial's rendering block (spec §2.6), also the twin's virtual plane
            "surface_point_m": [float(centre[0]), float(centre[1]), float(centre[2])],
            "surface_normal": [0.0, 0.0, 1.0],
            "stiffness_N_per_m": RENDER_STIFFNESS_N_PER_M,
            "static_friction": 0.0,
            "dynamic_friction": 0.0,
            "software": "haptify twin rendering loop (CHAI3D plane example)",
            "loop_rate_hz": 1000.0,
        }

    # -- descriptions -----------------------------------------------------------------------------
    def rig_description(self) -> dict:
        return rg.rig_description(self.cfg, self.layout, extra_markers=plate_loads.COP_MARKERS)

    def manifest(self) -> dict:
        name = self.opt.session_id or f"sim-{_slug(self.twin.name)}-s{self.opt.seed}"
        return {
            "session_id": name,
            "date": SESSION_DATE,
            "lab": {"id": self.opt.lab_id},
            "examiner": {"id": self.opt.examiner_id},
            "device": self.twin.device.model_dump(mode="json", exclude_none=True),
            "device_placement": self.twin.placement.model_dump(mode="json"),
            "rig": self.rig_description(),
            "recorder": f"haptify-twin {PACKAGE_VERSION}",
        }

    # -- one trial -------------------------------------------------------------------------------
    def run(self, p: PlannedTrial) -> TrialOutput:
        """Simulate one planned trial (it starts at ``p.t0`` on the session clock)."""
        t0 = p.t0
        rng_ex, rng_rig, rng_vib = trial_rng(self.opt.seed, p.trial_id)
        method = {
            "workspace": self._workspace,
            "rig.plate_bias": self._plate_bias,
            "rig.handle_calibration": self._handle_calibration,
            "rig.plate_impact": self._plate_impact,
            "rig.plate_cop": self._plate_cop,
            "rig.baseline_vibration": self._baseline,
        }.get(p.name, self._device_trial)
        return method(p, t0, rng_ex, rng_rig, rng_vib)

    def _trajectory(self, name: str, rng: np.random.Generator, t0: float) -> hand_path.HandTrajectory:
        """The examiner's hand path of a device protocol; speeds × ``examiner_pace`` (periods ÷ it), except the
        local dynamic protocol's oscillation band, which the protocol prescribes (paper §V-C)."""
        d, r, rate, pace = self.opt.duration(name), self.reach, self.opt.rate_hz, self.opt.examiner_pace
        z = self.surface["surface_point_m"][2]
        if name == "free_space":
            return ex.free_space_wander(
                rng,
                r,
                d,
                rate_hz=rate,
                t0=t0,
                mean_speed=pace * ex.FREE_SPACE_MEAN_SPEED,
                max_speed=pace * 0.75 * ex.FREE_SPACE_MAX_SPEED,
                mean_angular=pace * ex.FREE_SPACE_MEAN_ANGULAR,
                max_angular=pace * 0.75 * ex.FREE_SPACE_MAX_ANGULAR,
            )
        if name == "local_dynamic":
            return ex.local_oscillations(rng, r, d, rate_hz=rate, t0=t0)
        if name == "figure_eight":
            return ex.figure_eight(rng, r, d, rate_hz=rate, t0=t0, period_range_s=_paced(ex.FIGURE_EIGHT_PERIODS_S, pace))
        if name == "frictionless_surface":
            return ex.surface_circles(rng, r, z, d, rate_hz=rate, t0=t0, period_range_s=_paced(ex.SURFACE_PERIODS_S, pace))
        if name == "stiffness":
            return ex.surface_presses(rng, r, z, d, rate_hz=rate, t0=t0, press_speed=pace * ex.PRESS_SPEED)
        raise ValueError(f"no trajectory for {name!r}")

    def _device_trial(self, p, t0, rng_ex, rng_rig, rng_vib) -> TrialOutput:
        traj = self._trajectory(p.name, rng_ex, t0)
        cfg = self.cfg
        step = rg.decimation(traj.rate_hz, cfg.ft_rate_hz)
        t1k = traj.t[::step]
        active = p.name in ("frictionless_surface", "stiffness")
        res: ActiveResult | PassiveResult
        if active:
            res = simulate_active(self.twin, t1k, traj.position_W[::step], traj.quaternion_W[::step], self.surface)
        else:
            res = simulate_passive(self.twin, t1k, traj.position_W[::step], traj.quaternion_W[::step])
        streams, rates, entities, offsets = _no_streams()
        loads = rg.HandleLoads(res.force_W, res.torque_W)
        gain = trial_ft_gain(cfg, self.opt.seed, p.trial_id)
        streams["handle_wrench"] = {
            "t": t1k,
            **rg.handle_wrench(
                rng_rig,
                cfg,
                position_W=traj.position_W,
                quaternion_W=traj.quaternion_W,
                rate_hz=traj.rate_hz,
                loads=loads,
                bias_force=self.bias_f,
                bias_torque=self.bias_t,
                connector_mass=self.conn_m,
                connector_com_S=self.conn_r,
                gain=gain,
            ),
        }
        rates["handle_wrench"] = cfg.ft_rate_hz
        vib = device_vibration(self.twin, traj.t, traj.speed(), rng_vib)
        accel_truth = self._accel(streams, rates, offsets, traj, rng_rig, vib)
        streams["plate_wrench"] = {
            "t": t1k,
            **rg.plate_wrench(
                rng_rig,
                cfg,
                force_W=res.base_force_W,
                moment_W=res.base_torque_W,
                bias_force=self.bias_p,
                errors=self.plate_errors,
            ),
        }
        rates["plate_wrench"] = cfg.plate_rate_hz
        q_step = rg.decimation(cfg.ft_rate_hz, cfg.mocap_rate_hz)
        self._mocap(streams, rates, entities, offsets, traj, res.q[::q_step], rng_rig)
        if isinstance(res, ActiveResult):
            streams["commanded_wrench"] = {
                "t": t1k,
                **{c: res.commanded_W[:, k] for k, c in enumerate(("fx", "fy", "fz", "tx", "ty", "tz"))},
            }
            rates["commanded_wrench"] = cfg.ft_rate_hz
            streams["device_joint_angles"] = {
                "t": t1k,
                **{f"q{k + 1}": res.encoder_q[:, k] for k in range(res.encoder_q.shape[1])},
            }
            rates["device_joint_angles"] = cfg.ft_rate_hz
        self._sync(streams, rates, t1k, t0)
        a_c = rg.connector_motion(
            cfg, position_W=traj.position_W, quaternion_W=traj.quaternion_W, rate_hz=traj.rate_hz, connector_com_S=self.conn_r
        )[3]
        arrays = {
            "t": t1k,
            "position_W": traj.position_W[::step],
            "quaternion_W": traj.quaternion_W[::step],
            "q": res.q,
            "gimbal": res.gimbal,
            "force_W": res.force_W,
            "torque_W": res.torque_W,
            "connector_inertia_W": self.conn_m * a_c,
            "base_force_W": res.base_force_W,
            "base_torque_W": res.base_torque_W,
            "reachable": res.ok,
            "vibration_W_2kHz": vib,
            **accel_truth,
        }
        if isinstance(res, ActiveResult):
            arrays.update(
                {
                    "commanded_W": res.commanded_W,
                    "encoder_q": res.encoder_q,
                    "motor_torque": res.motor_torque,
                    "cable_torque": res.cable_torque,
                    "saturated": res.saturated,
                    "cut_off": res.cut_off,
                }
            )
        truth = {"examiner": traj.meta, "clock_offsets_s": offsets, "reachable_fraction": float(np.mean(res.ok)), "ft_gain": gain}
        return TrialOutput(
            p, active, streams, rates, entities, dict(self.surface) if active else None, truth, arrays, float(traj.t[-1])
        )

    def _workspace(self, p, t0, rng_ex, rng_rig, rng_vib) -> TrialOutput:
        traj = ex.boundary_sweep(rng_ex, self.reach, self.opt.duration("workspace"), rate_hz=self.opt.rate_hz, t0=t0)
        cfg = self.cfg
        step = rg.decimation(traj.rate_hz, cfg.mocap_rate_hz)
        q, gimbal, ok = hand_to_joints(self.twin, traj.position_W[::step], traj.quaternion_W[::step])
        streams, rates, entities, offsets = _no_streams()
        self._mocap(streams, rates, entities, offsets, traj, q, rng_rig)
        self._sync(streams, rates, traj.t[:: rg.decimation(traj.rate_hz, cfg.sync_rate_hz)], t0)
        arrays = {
            "t": traj.t[::step],
            "position_W": traj.position_W[::step],
            "quaternion_W": traj.quaternion_W[::step],
            "q": q,
            "gimbal": gimbal,
            "reachable": ok,
        }
        truth = {"examiner": traj.meta, "clock_offsets_s": offsets}
        return TrialOutput(p, False, streams, rates, entities, None, truth, arrays, float(traj.t[-1]))

    def _handle_calibration(self, p, t0, rng_ex, rng_rig, rng_vib) -> TrialOutput:
        traj = ex.handle_rotation(rng_ex, self.opt.duration(p.name), rate_hz=self.opt.rate_hz, t0=t0)
        cfg = self.cfg
        streams, rates, entities, offsets = _no_streams()
        t1k = traj.t[:: rg.decimation(traj.rate_hz, cfg.ft_rate_hz)]
        gain = trial_ft_gain(cfg, self.opt.seed, p.trial_id)
        streams["handle_wrench"] = {
            "t": t1k,
            **rg.handle_wrench(
                rng_rig,
                cfg,
                position_W=traj.position_W,
                quaternion_W=traj.quaternion_W,
                rate_hz=traj.rate_hz,
                loads=None,
                bias_force=self.bias_f,
                bias_torque=self.bias_t,
                connector_mass=self.conn_m,
                connector_com_S=self.conn_r,
                gain=gain,
            ),
        }
        rates["handle_wrench"] = cfg.ft_rate_hz
        accel_truth = self._accel(streams, rates, offsets, traj, rng_rig, None)
        self._handle_pose(streams, rates, offsets, traj, rng_rig)
        self._sync(streams, rates, t1k, t0)
        out = self._hand_only(p, traj, streams, rates, entities, offsets, t1k, accel_truth)
        out.truth["ft_gain"] = gain
        return out

    def _hand_only(self, p, traj, streams, rates, entities, offsets, t1k, accel_truth) -> TrialOutput:
        """A trial of the handle alone (no device): truth is the hand path at 1 kHz and the perfect
        accelerometer's reading (:meth:`_accel`)."""
        step = rg.decimation(traj.rate_hz, self.cfg.ft_rate_hz)
        arrays = {"t": t1k, "position_W": traj.position_W[::step], "quaternion_W": traj.quaternion_W[::step], **accel_truth}
        return TrialOutput(
            p,
            False,
            streams,
            rates,
            entities,
            None,
            {"examiner": traj.meta, "clock_offsets_s": offsets},
            arrays,
            float(traj.t[-1]),
        )

    def _baseline(self, p, t0, rng_ex, rng_rig, rng_vib) -> TrialOutput:
        traj = ex.baseline_wander(rng_ex, self.opt.duration(p.name), rate_hz=self.opt.rate_hz, t0=t0)
        streams, rates, entities, offsets = _no_streams()
        accel_truth = self._accel(streams, rates, offsets, traj, rng_rig, None)
        self._handle_pose(streams, rates, offsets, traj, rng_rig)
        t1k = traj.t[:: rg.decimation(traj.rate_hz, self.cfg.sync_rate_hz)]
        self._sync(streams, rates, t1k, t0)
        return self._hand_only(p, traj, streams, rates, entities, offsets, t1k, accel_truth)

    def _plate_trial(self, p, t0, load: plate_loads.PlateLoad | None, duration: float, rng_rig) -> TrialOutput:
        cfg = self.cfg
        t = load.t if load is not None else hand_path.clock(duration, cfg.plate_rate_hz, t0)
        force = load.force_W if load is not None else np.zeros((len(t), 3))
        point = load.point_W if load is not None else np.zeros((len(t), 3))
        streams, rates, entities, offsets = _no_streams()
        streams["plate_wrench"] = {
            "t": t,
            **rg.plate_wrench(
                rng_rig, cfg, force_W=force, moment_W=np.cross(point, force), bias_force=self.bias_p, errors=self.plate_errors
            ),
        }
        rates["plate_wrench"] = cfg.plate_rate_hz
        arrays = {"t": t, "force_W": force, "point_W": point}
        if load is not None and load.markers_W:
            step = rg.decimation(load.rate_hz, cfg.mocap_rate_hz)
            off = rg.clock_offset(rng_rig, cfg)
            cols, _ = rg.mocap_markers(rng_rig, cfg, {k: v[::step] for k, v in load.markers_W.items()})
            streams["markers"] = {"t": t[::step] - off, **cols}
            rates["markers"] = cfg.mocap_rate_hz
            entities["markers"] = list(load.markers_W)
            offsets["markers"] = off
        self._sync(streams, rates, t, t0)
        meta = load.meta if load is not None else {"load": "none (plate unloaded)"}
        return TrialOutput(
            p, False, streams, rates, entities, None, {"load": meta, "clock_offsets_s": offsets}, arrays, float(t[-1])
        )

    def _plate_bias(self, p, t0, rng_ex, rng_rig, rng_vib) -> TrialOutput:
        return self._plate_trial(p, t0, None, self.opt.duration(p.name), rng_rig)

    def _plate_impact(self, p, t0, rng_ex, rng_rig, rng_vib) -> TrialOutput:
        load = plate_loads.ball_impact(rng_ex, self.opt.duration(p.name), rate_hz=self.cfg.plate_rate_hz, t0=t0)
        return self._plate_trial(p, t0, load, 0.0, rng_rig)

    def _plate_cop(self, p, t0, rng_ex, rng_rig, rng_vib) -> TrialOutput:
        load = plate_loads.weight_placements(
            rng_ex, rate_hz=self.cfg.plate_rate_hz, t0=t0, dwell_s=cop_dwell(self.opt), move_s=plate_loads.COP_MOVE_S
        )
        return self._plate_trial(p, t0, load, 0.0, rng_rig)

    # -- stream helpers --------------------------------------------------------------------------
    def _accel(self, streams, rates, offsets, traj, rng_rig, vib) -> dict[str, np.ndarray]:
        """The handle_accel stream; returns its truth arrays: times and a perfect accelerometer's reading."""
        cfg = self.cfg
        t2k = traj.t[:: rg.decimation(traj.rate_hz, cfg.accel_rate_hz)]
        floor = rg.noise_floor(rng_rig, len(t2k), cfg.accel_rate_hz, self.twin.rig.accel_floor)
        off = rg.clock_offset(rng_rig, cfg)
        true_a = rg.specific_force(
            cfg, position_W=traj.position_W, quaternion_W=traj.quaternion_W, rate_hz=traj.rate_hz, vibration_W=vib, floor_W=floor
        )
        streams["handle_accel"] = {"t": t2k - off, **rg.handle_accel(rng_rig, cfg, specific_force_A=true_a, bias=self.bias_a)}
        rates["handle_accel"] = cfg.accel_rate_hz
        offsets["handle_accel"] = off
        return {"accel_t": t2k, "accel_A": true_a}

    def _handle_pose(self, streams, rates, offsets, traj, rng_rig, occluded=None, off=None) -> None:
        cfg = self.cfg
        step = rg.decimation(traj.rate_hz, cfg.mocap_rate_hz)
        if occluded is None:
            n = len(traj.t[::step])
            masks = [
                rg.occlusion_mask(rng_rig, n, cfg.mocap_rate_hz, cfg.occlusion_rate_per_s, cfg.occlusion_mean_s)
                for _ in range(len(self.layout["handle"]))
            ]
            occluded = np.any(masks, axis=0)
        if off is None:
            off = rg.clock_offset(rng_rig, cfg)
        pos, quat = rg.pose_noise(rng_rig, cfg, traj.position_W[::step], traj.quaternion_W[::step], len(self.layout["handle"]))
        cols = rg.pose_columns("", pos, quat, occluded)
        streams["handle_pose"] = {"t": traj.t[::step] - off, **cols}
        rates["handle_pose"] = cfg.mocap_rate_hz
        offsets["handle_pose"] = off

    def _mocap(self, streams, rates, entities, offsets, traj, q, rng_rig) -> None:
        """handle_pose, markers (every body) and link_poses at the mocap rate from the true pose and joints."""
        cfg = self.cfg
        step = rg.decimation(traj.rate_hz, cfg.mocap_rate_hz)
        t = traj.t[::step]
        pos_h, quat_h = traj.position_W[::step], traj.quaternion_W[::step]
        frames = link_transforms(self.kin, q)  # device frame, frames 0..n
        r_wd = _rot(self.twin.placement.quaternion)
        bodies: dict[str, tuple[np.ndarray, np.ndarray]] = {}
        n = len(t)
        base_p = np.broadcast_to(np.asarray(self.twin.placement.position, float), (n, 3))
        base_q = np.broadcast_to(np.asarray(self.twin.placement.quaternion, float), (n, 4))
        bodies["base"] = (base_p, base_q)
        for i, name in enumerate(self.link_names):
            f = frames[i + 1]
            p_w = device_to_world(self.twin, f[:, :3, 3])
            r_w = np.einsum("ij,njk->nik", r_wd, f[:, :3, :3])
            bodies[name] = (p_w, matrix_to_quat(r_w))
        bodies["handle"] = (pos_h, quat_h)
        truth_markers = {}
        for body, pts in self.layout.items():
            p, qq = bodies[body]
            for m, local in zip(rg.marker_names(body, len(pts)), pts):
                truth_markers[m] = pose_apply(p, qq, np.broadcast_to(local, (n, 3)))
        cols, masks = rg.mocap_markers(rng_rig, cfg, truth_markers)
        off = rg.clock_offset(rng_rig, cfg)
        streams["markers"] = {"t": t - off, **cols}
        rates["markers"] = cfg.mocap_rate_hz
        entities["markers"] = list(truth_markers)
        offsets["markers"] = off
        link_cols: dict[str, np.ndarray] = {}
        for body in ["base", *self.link_names]:
            p, qq = bodies[body]
            occ = np.any([masks[m] for m in rg.marker_names(body, len(self.layout[body]))], axis=0)
            pn, qn = rg.pose_noise(rng_rig, cfg, np.array(p), np.array(qq), len(self.layout[body]))
            link_cols.update(rg.pose_columns(f"{body}_", pn, qn, occ))
        streams["link_poses"] = {"t": t - off, **link_cols}
        rates["link_poses"] = cfg.mocap_rate_hz
        entities["link_poses"] = ["base", *self.link_names]
        occluded = np.any([masks[m] for m in rg.marker_names("handle", len(self.layout["handle"]))], axis=0)
        self._handle_pose(streams, rates, offsets, traj, rng_rig, occluded=occluded, off=off)

    def _sync(self, streams, rates, t, t0) -> None:
        streams["sync"] = {"t": t, **rg.sync_trigger(self.cfg, t, t0)}
        rates["sync"] = self.cfg.sync_rate_hz


def _rot(q) -> np.ndarray:
    return quat_to_matrix(np.asarray(q, float))


def _slug(text: str) -> str:
    out = "".join(c if c.isalnum() else "-" for c in text.lower()).strip("-")
    return "-".join(filter(None, out.split("-")))[:40] or "twin"


# --- the dossier -----------------------------------------------------------------------------------


@dataclass
class DossierResult:
    """What :func:`simulate_dossier` wrote: folders and files, trial ids, recorded time and timings (s)."""

    out_dir: Path
    session: Path
    truth_json: Path
    truth_npz: Path
    trials: list[str]
    recorded_s: float
    timings_s: dict[str, float] = field(default_factory=dict)


def simulate_dossier(
    twin: TwinFile,
    out_dir: str | os.PathLike,
    options: SimulationOptions | None = None,
    *,
    overwrite: bool = False,
    advance: Callable[[int], object] | None = None,
) -> DossierResult:
    """Simulate every planned trial and write ``<out>/session``, ``<out>/truth.json`` and ``<out>/truth.npz``.

    ``advance(n)`` is called after each trial (for a progress bar). The output folder is built beside
    the target and renamed into place, so an interrupted run leaves nothing half-written (spec §3.6).
    E901 when ``out_dir`` exists and not ``overwrite``.
    """
    opt = options or SimulationOptions()
    out = Path(out_dir)
    if out.exists() and not overwrite:
        raise fail("E901", f"{str(out)!r} already exists", file=str(out))
    sim = DossierSimulator(twin, opt)
    writer = SessionWriter(manifest=sim.manifest(), compact=opt.compact)
    trials_truth, arrays, clock_records = [], {}, []
    recorded = 0.0
    planned = plan(opt)
    clock0 = time.perf_counter()
    for p, res in zip(planned, _run_all(sim, planned, opt.workers)):
        writer.add_trial(
            p.trial_id,
            p.protocol,
            powered=res.powered,
            repetition=p.repetition,
            label=p.label,
            rendering=res.rendering,
            notes="simulated by the haptify device twin",
        )
        for kind, cols in res.streams.items():
            stream = writer.add_stream(
                p.trial_id, kind, cols, rate_hz=res.rates[kind], fmt=opt.fmt, entities=res.entities.get(kind)
            )
            off = res.truth.get("clock_offsets_s", {}).get(kind, 0.0)
            if off:
                clock_records.append(
                    {"kind": "clock_offset", "id": f"clock-{p.trial_id}-{kind}", "stream_file": stream["file"], "offset_s": off}
                )
        trials_truth.append(
            {
                "id": p.trial_id,
                "protocol": p.protocol,
                "label": p.label,
                "repetition": p.repetition,
                "t_start_s": p.t0,
                "t_end_s": res.end_time,
                **res.truth,
            }
        )
        for key, val in res.arrays.items():
            arrays[f"{p.trial_id}/{key}"] = _truth_array(key, val)
        recorded += res.end_time - p.t0
        if advance is not None:
            advance(1)
    timings = {"simulate": time.perf_counter() - clock0}
    if clock_records:
        writer.manifest = {**writer.manifest, "calibration": clock_records}
    truth = {
        "format": "haptify-twin-truth",
        "version": "1.0",
        "seed": opt.seed,
        "reps": opt.reps,
        "examiner": {"id": opt.examiner_id, "pace": opt.examiner_pace},
        "protocols": list(opt.protocols),
        "session_folder": "session",
        "twin": twin_to_dict(twin),
        "rig": {
            "config": opt.rig.to_dict(),
            "marker_layout_m": {k: v.tolist() for k, v in sim.layout.items()},
            "cop_marker_offsets_m": plate_loads.COP_MARKER_OFFSETS.tolist(),
            "plate_corner_positions_m": sim.plate_errors.positions.tolist(),
            "plate_corner_gains": sim.plate_errors.gains.tolist(),
        },
        "effective": {
            "handle_force_bias_N": sim.bias_f.tolist(),
            "handle_torque_bias_Nm": sim.bias_t.tolist(),
            "accel_bias_m_per_s2": sim.bias_a.tolist(),
            "plate_corner_force_bias_N": sim.bias_p.tolist(),
            "connector_mass_kg": sim.conn_m,
            "connector_com_m": sim.conn_r.tolist(),
            "rendering": sim.surface,
        },
        "trials": trials_truth,
        "arrays_file": "truth.npz",
        "arrays_note": "per trial '<trial id>/<name>': true signals at 1 kHz (workspace: 100 Hz; vibration_W_2kHz: "
        "2 kHz), SI units, W frame; float32 except the time base 't' (float64, session clock)",
    }
    with built_in_place(out) as build:
        from concurrent.futures import ThreadPoolExecutor

        clock0 = time.perf_counter()
        # Parquet and deflate both release the GIL: write the truth arrays while the session is written.
        with ThreadPoolExecutor(max_workers=1) as pool:
            npz = pool.submit(write_npz, build / "truth.npz", arrays)
            writer.write(build / "session")
            timings["write_session"] = time.perf_counter() - clock0
            npz.result()
        atomic_write_json(build / "truth.json", _jsonable(truth))
        timings["write_all"] = time.perf_counter() - clock0
    return DossierResult(
        out, out / "session", out / "truth.json", out / "truth.npz", [p.trial_id for p in planned], recorded, timings
    )


_WORKER: DossierSimulator | None = None


def _init_worker(twin: TwinFile, options: SimulationOptions) -> None:
    global _WORKER
    _WORKER = DossierSimulator(twin, options)


def _run_in_worker(p: PlannedTrial) -> TrialOutput:
    assert _WORKER is not None
    return _WORKER.run(p)


def _run_all(sim: DossierSimulator, planned: list[PlannedTrial], workers: int):
    """Trial outputs in plan order; with more than one worker the trials run in parallel processes.

    Results do not depend on the number of workers (every trial has its own seeded generators).
    """
    n = workers or min(4, os.cpu_count() or 1)
    n = min(n, len(planned))
    if n <= 1:
        for p in planned:
            yield sim.run(p)
        return
    import multiprocessing as mp
    from concurrent.futures import ProcessPoolExecutor

    # longest trials first keeps both workers busy; results are yielded in plan order
    order = sorted(range(len(planned)), key=lambda i: -planned_duration(planned[i].name, sim.opt))
    ctx = mp.get_context("fork") if "fork" in mp.get_all_start_methods() else None
    with ProcessPoolExecutor(max_workers=n, mp_context=ctx, initializer=_init_worker, initargs=(sim.twin, sim.opt)) as pool:
        futures = {i: pool.submit(_run_in_worker, planned[i]) for i in order}
        for i in range(len(planned)):
            yield futures[i].result()


def write_npz(path: Path, arrays: dict[str, np.ndarray], level: int = 1) -> None:
    """Write arrays as a deflate-compressed ``.npz`` (readable by ``numpy.load``) at a fast compression level."""
    with zipfile.ZipFile(path, "w", compression=zipfile.ZIP_DEFLATED, compresslevel=level) as zf:
        for name, arr in arrays.items():
            with zf.open(name + ".npy", "w", force_zip64=True) as fh:
                np.lib.format.write_array(fh, np.asarray(arr), allow_pickle=False)


def _truth_array(key: str, value) -> np.ndarray:
    """Truth arrays in float32 (ample for SI signals of this size: 0.1 µm at 1 m), except the time base."""
    arr = np.asarray(value)
    return arr.astype(np.float32) if arr.dtype == np.float64 and key != "t" else arr


def _jsonable(obj):
    """Numbers and arrays as plain JSON values (NaN never occurs in the truth)."""
    if isinstance(obj, dict):
        return {str(k): _jsonable(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_jsonable(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    if isinstance(obj, (np.floating, np.integer, np.bool_)):
        return obj.item()
    return obj
