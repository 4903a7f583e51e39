"""Spread and bias of ``stiffness.measured`` over seeds of the simulated Touch (issue 16: SD/mean ≤ 2 %,
bias to the twin's truth ≤ 5 %), and how far neighbouring fit windows move it (spec §13.2).

Per variant of the ``touch`` preset and seed: one 30 s stiffness trial (the examiner's presses at the
workspace centre, the rig's realistic noise: motion capture 0.15 mm per marker with occlusions, F/T
0.02 N) and the handle calibration trial, simulated by the device twin and computed by the reference
(``compute_session``). The truth is known by construction from the twin's parameters along the press path
(straight down through the rendering's plane point, true kinematics):

- ``spring``: the commanded 750 N/m in series with the cable drive, ``1 / (1/k_r + nᵀ J C⁻¹ K⁻¹ C⁻ᵀ Jᵀ n)``;
- ``felt``: what the loading stroke renders — the spring, plus the slope of the device's weight along the
  press (no gravity compensation), plus the slope of the drive friction along the press (Coulomb level with
  its ripple along the drum, at the examiner's 0.04 m/s), the latter scaled by ``k_spring / k_r`` because
  the motors feel it through the cables (the encoders see the cable stretch it causes).

Both slopes are least-squares slopes over the middle 80 % of the linear range (plane to the depth where
the spring reaches the torque limit). Variants: ``touch`` (the preset), ``no-ripple`` (friction constant
along the drum: ``felt`` differs from ``spring`` by the weight only), ``frictionless`` (no drive friction:
the case whose fitted stiffness came out at −7 N/m before the peak was taken on the loading stroke).

``python benchmarks/bench_stiffness_spread.py [SEEDS [VARIANT,…]]`` (default 10 seeds, every variant:
40–80 s on the shared 2 cores).
"""

from __future__ import annotations

import sys
import tempfile
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

from haptify.processing import kinematics as ref
from haptify.pipeline.compute import ComputeContext, compute_session
from haptify.metrics.stiffness import FitRule, fit_stiffness, grid_rate
from haptify.formats.storage import open_session
from haptify.metrics.surface import contact_signals
from haptify_tools.twin import kinematics as tk
from haptify_tools.twin.model import disable, preset, set_param
from haptify_tools.twin.physics import drive_friction, potential_energy
from haptify_tools.twin.simulate import RENDER_STIFFNESS_N_PER_M, SimulationOptions, simulate_dossier

PRESS_SPEED = 0.04          # m/s, the examiner's nominal press speed (twin.examiner.surface_presses)
SPREAD_TARGET, BIAS_TARGET = 2.0, 5.0   # %


def variant(name: str):
    """The Touch preset as the variant ``name`` renders it."""
    tw = preset("touch")
    if name == "no-ripple":
        return set_param(tw, "friction.coulomb.ripple_fraction", 0.0)
    if name == "frictionless":
        for effect in ("friction.coulomb", "friction.viscous", "friction.stribeck"):
            tw = disable(tw, effect)
        return tw
    if name != "touch":
        raise SystemExit(f"unknown variant {name!r}: touch, no-ripple, frictionless")
    return tw


VARIANTS = ("touch", "no-ripple", "frictionless")


def truth(tw, plane_point: np.ndarray, k_r: float = RENDER_STIFFNESS_N_PER_M) -> tuple[float, float]:
    """(spring, felt) stiffness in N/m along a press straight down through ``plane_point`` (W), from the
    twin's parameters (module docstring)."""
    kin = tk.true_kinematics(tw)
    c = np.asarray(tw.drive.coupling, float)
    c_inv = np.linalg.inv(c)
    k_cable = np.diag(tw.effects.drive_series_elasticity.stiffness_Nm_per_rad)
    r_wd, _ = tk.placement_matrix(tw)
    n_d = r_wd.T @ np.array([0.0, 0.0, 1.0])
    depth = np.linspace(0.0, 0.02, 401)
    q, _, ok = tk.hand_to_joints(tw, plane_point[None, :] - depth[:, None] * np.array([0.0, 0.0, 1.0]))
    jac = ref.jacobian(kin, q)
    compliance = np.einsum("i,nij,j->n", n_d, jac @ c_inv @ np.linalg.inv(k_cable) @ c_inv.T @ np.transpose(jac, (0, 2, 1)), n_d)
    spring = 1.0 / (1.0 / k_r + compliance)
    # the linear range ends where the spring force needs the torque limit on some drive axis
    axis_per_newton = np.abs(np.einsum("ij,njk,k->ni", c_inv.T, np.transpose(jac, (0, 2, 1)), n_d))
    limit = np.asarray(tw.effects.drive_torque_saturation.max_torque_Nm, float)
    knee = depth[np.argmax(spring * depth * np.max(axis_per_newton / limit, axis=1) >= 1.0)]
    sel = ok & (depth >= 0.1 * knee) & (depth <= 0.9 * knee)
    weight = np.gradient(potential_energy(tw, q), depth)          # normal force of the device's weight on the hand, N
    theta = q @ c.T
    omega = np.gradient(theta, depth, axis=0) * PRESS_SPEED
    tau = drive_friction(tw, omega, theta) @ c                      # joint torques of the drive friction
    friction = np.einsum("nj,j->n", np.linalg.solve(np.transpose(jac, (0, 2, 1)), tau[..., None])[..., 0], n_d)
    k_s = float(np.mean(spring[sel]))
    slope = lambda y: float(np.polyfit(depth[sel], y[sel], 1)[0])  # noqa: E731
    return k_s, k_s + slope(weight) + k_s / k_r * slope(friction)


def neighbours(rule: FitRule) -> dict[str, FitRule]:
    """Fit windows next to the normative one: contact transient ±2 samples, top share 0.8 / 0.95, hold ½× / 2×."""
    return {"settle-2": replace(rule, settle=rule.settle - 2), "settle+2": replace(rule, settle=rule.settle + 2),
            "high 0.8": replace(rule, high=0.8), "high 0.95": replace(rule, high=0.95),
            "hold/2": replace(rule, hold=rule.hold // 2), "hold*2": replace(rule, hold=rule.hold * 2)}


def one(name: str, seed: int, folder: Path) -> dict:
    """Simulate and compute one seed of a variant: value, presses, fit samples, neighbouring windows' values."""
    tw = variant(name)
    opt = SimulationOptions(protocols=("stiffness", "rig.handle_calibration"), reps=1, seed=seed, rig_trials=False,
                            workers=1)
    session = open_session(simulate_dossier(tw, folder / f"{name}-{seed}", opt).session)
    ctx = ComputeContext(session=session)
    res = compute_session(session, ["stiffness.measured", "stiffness.peak_force"], ctx=ctx)
    m = {r.id: r for r in res.metrics}
    if "stiffness.measured" not in m:
        return {"value": float("nan"), "codes": [u.code for u in res.unavailable]}
    tid = session.trials_of("stiffness")[0].id
    cs = contact_signals(ctx, tid)
    rule = FitRule.at_rate(grid_rate(cs.t))
    alt = {k: fit_stiffness(cs.t, cs.penetration, cs.normal_force, cs.contact, tid, cs.valid, r).stiffness
           for k, r in neighbours(rule).items()}
    diag = m["stiffness.measured"].diagnostics
    return {"value": m["stiffness.measured"].value, "peak": m["stiffness.peak_force"].value, "presses": diag["presses"][0],
            "fit_samples": diag["press_fit_samples"][0], "alt": alt, "plane": np.asarray(cs.plane_point),
            "codes": [w.code for w in res.warnings]}


def main() -> int:
    seeds = int(sys.argv[1]) if len(sys.argv) > 1 else 10
    names = sys.argv[2].split(",") if len(sys.argv) > 2 else list(VARIANTS)
    with tempfile.TemporaryDirectory(prefix="bench-stiffness-") as tmp:
        for name in names:
            t0 = time.perf_counter()
            rows = [one(name, s, Path(tmp)) for s in range(seeds)]
            spring, felt = truth(variant(name), rows[0]["plane"])
            print(f"\n# variant {name}: truth spring {spring:.1f} N/m, felt on the loading stroke {felt:.1f} N/m")
            for s, r in enumerate(rows):
                print(f"seed {s}: stiffness.measured {r['value']:.1f} N/m, peak {r.get('peak', float('nan')):.3f} N, "
                      f"{r.get('presses', 0)} presses, fit samples {r.get('fit_samples')}, findings {r['codes'] or '-'}")
            values = np.array([r["value"] for r in rows])
            mean = float(np.mean(values))
            spread = 100.0 * float(np.std(values, ddof=1)) / mean
            print(f"{name} mean stiffness.measured: {mean:.1f} N/m over {seeds} seeds")
            print(f"{name} SD/mean: {spread:.2f} % (target <= {SPREAD_TARGET:g} %)")
            print(f"{name} bias to the felt truth: {100.0 * (mean / felt - 1):+.2f} % (target |bias| <= {BIAS_TARGET:g} %)")
            print(f"{name} bias to the spring alone: {100.0 * (mean / spring - 1):+.2f} %")
            for key in rows[0]["alt"]:
                shift = 100.0 * (np.mean([r["alt"][key] for r in rows]) / mean - 1)
                print(f"{name} window {key}: mean moves {shift:+.2f} %")
            print(f"{name} time: {(time.perf_counter() - t0) / seeds:.1f} s per seed")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
