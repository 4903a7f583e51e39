"""One planned trial of a simulated dossier as raw streams and truth (design §4; spec chapter 2 streams):
the examiner's hand path, the twin's physics (passive or active), the virtual rig's sensors (handle F/T,
accelerometer, motion capture, force plate, sync) and the rig's calibration trials."""

from __future__ import annotations

import zlib
from dataclasses import dataclass
from typing import Any

import numpy as np

from haptify.formats.conventions import matrix_to_quat, pose_apply, quat_to_matrix
from haptify.versions import PACKAGE_VERSION
from haptify_tools.twin import examiner as ex
from haptify_tools.twin import hand_path, plate_loads
from haptify_tools.twin import rig as rg
from haptify_tools.twin.dossier_plan import (
    RENDER_STIFFNESS_N_PER_M,
    SESSION_DATE,
    PlannedTrial,
    SimulationOptions,
    _paced,
    cop_dwell,
    trial_ft_gain,
    trial_rng,
)
from haptify_tools.twin.kinematics import device_to_world, hand_to_joints, link_transforms, true_kinematics
from haptify_tools.twin.model import TwinFile
from haptify_tools.twin.physics import ActiveResult, PassiveResult, simulate_active, simulate_passive
from haptify_tools.twin.reach import reach_from_twin
from haptify_tools.twin.vibration_model import device_vibration


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
        gain = self._handle_wrench(streams, rates, p, traj, t1k, rng_rig, loads)
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

    def _handle_wrench(self, streams, rates, p, traj, t1k, rng_rig, loads) -> float:
        """The trial's handle_wrench stream at the F/T rate: the hand's ``loads`` (None: the handle alone) with the
        session's biases, connector and the trial's F/T gain, which it returns."""
        cfg = self.cfg
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
        return gain

    def _handle_calibration(self, p, t0, rng_ex, rng_rig, rng_vib) -> TrialOutput:
        traj = ex.handle_rotation(rng_ex, self.opt.duration(p.name), rate_hz=self.opt.rate_hz, t0=t0)
        cfg = self.cfg
        streams, rates, entities, offsets = _no_streams()
        t1k = traj.t[:: rg.decimation(traj.rate_hz, cfg.ft_rate_hz)]
        gain = self._handle_wrench(streams, rates, p, traj, t1k, rng_rig, None)
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
