"""The workspace part of the discrepancy workflow: the base-collision candidate (discrepancy README §2; paper §VI-A, Fig. 5).

The workspace protocol records only positions, so the twin is compared with it through the examiner's
own rule (:meth:`haptify_tools.twin.reach.Reach.radial_stop`): every measured point is mapped to its
unit joint coordinates ``s`` with the twin's kinematics and projected from the joint box's centre onto
the box's face, ``s_face`` — the command the examiner was following; the twin then predicts where the
hand stops on the way out to ``s_face`` (the face itself when nothing is in the way, the first contact
with the base otherwise). The residual is measured minus predicted position (m, W). A twin without the
base collision predicts the whole joint box: the Touch's missing lower lobe shows up as a large
residual there.

Candidate ``kinematics.base_collision``: the box primitive of the twin file's (disabled) collision
geometry with its TOP height identified (``base_top_m``, device frame; the bottom stays on the table),
by the same 1-D search, scores and acceptance rules as the force candidates (:mod:`.stats`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from haptify.codes import Code
from haptify.errors import fail
from haptify.formats.storage import SessionFolder
from haptify.metrics.workspace import measured_points
from haptify.processing.kinematics import joint_limits
from haptify_tools.twin.kinematics import hand_to_joints, true_kinematics
from haptify_tools.twin.model import Box, TwinFile, twin_from_dict, twin_to_dict
from haptify_tools.twin.reach import reach_from_twin

EFFECT_ID = "kinematics.base_collision"
PARAMETER = "base_top_m"
GRID_FACTORS = (0.5, 0.7, 1.0, 1.4, 2.0)  # of the stored box's height above its bottom


@dataclass
class MeasuredSweep:
    """The measured workspace points of one trial (W, m) on the mocap clock; ``valid``: usable rows (discrepancy README §1)."""

    trial_id: str
    t: np.ndarray
    position: np.ndarray
    valid: np.ndarray


def load_sweeps(session: SessionFolder) -> list[MeasuredSweep]:
    """Every workspace trial's measured points (the reference's ``measured_points``, spec §8.2)."""
    out = []
    for trial in session.trials_of("workspace"):
        pts = measured_points(session, trial.id)
        if len(pts) < 20:
            continue
        out.append(MeasuredSweep(trial.id, np.arange(len(pts), dtype=float), pts, np.ones(len(pts), bool)))
    return out


def _box_index(twin: TwinFile) -> int | None:
    prims = twin.effects.kinematics_base_collision.primitives
    return next((i for i, p in enumerate(prims) if p.shape == "box"), None)


def _the_box(twin: TwinFile) -> tuple[int, Box]:
    """The first box primitive of the twin's collision and its index; E802 when there is none."""
    prims = twin.effects.kinematics_base_collision.primitives
    found = next(((i, p) for i, p in enumerate(prims) if isinstance(p, Box)), None)
    if found is None:
        raise fail(
            Code.TWIN_FILE_INVALID,
            f"the twin's {EFFECT_ID} holds no box primitive",
            pointer=f"/effects/{EFFECT_ID}/primitives",
            expected="a primitive of shape 'box'",
        )
    return found


def available(twin: TwinFile) -> bool:
    """The candidate ``kinematics.base_collision`` is offered when the twin's collision is off and its file holds a box primitive (discrepancy README §2)."""
    return not twin.on(EFFECT_ID) and _box_index(twin) is not None


def box_top(twin: TwinFile) -> tuple[float, float]:
    """(top, bottom) heights of the collision box in the device frame, m (discrepancy README §2, ``base_top_m``)."""
    _, box = _the_box(twin)
    return box.center_m[2] + box.half_extents_m[2], box.center_m[2] - box.half_extents_m[2]


def apply(twin: TwinFile, top: float) -> TwinFile:
    """A copy of ``twin`` with the base collision on and its box's top at ``top`` m (bottom unchanged) (discrepancy README §2)."""
    i, _ = _the_box(twin)
    _, bottom = box_top(twin)
    data = twin_to_dict(twin)
    box = data["effects"][EFFECT_ID]["primitives"][i]
    half = max(0.5 * (top - bottom), 1e-4)
    box["center_m"] = [box["center_m"][0], box["center_m"][1], bottom + half]
    box["half_extents_m"] = [box["half_extents_m"][0], box["half_extents_m"][1], half]
    data["effects"][EFFECT_ID]["enabled"] = True
    return twin_from_dict(data)


def face_commands(twin: TwinFile, points_W: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Unit joint coordinates on the joint box's faces ``(N, 3)`` that the examiner was heading for at each
    measured point, and ``ok`` (the point is within the twin's reach) (discrepancy README §1).
    """
    kin = true_kinematics(twin)
    q, _, _ = hand_to_joints(twin, points_W)
    lo, hi = joint_limits(kin, q)
    span = np.where(hi - lo > 0, hi - lo, np.nan)
    s = (q - lo) / span
    d = s - 0.5
    m = np.max(np.abs(d), axis=1)
    # points a little outside the joint box (motion-capture noise on the boundary) keep their clipped command
    ok = np.isfinite(m) & (m > 1e-6) & np.all((s > -0.1) & (s < 1.1), axis=1)
    face = 0.5 + d * (0.5 / np.where(ok, m, 1.0))[:, None]
    return np.clip(face, 0.0, 1.0), ok


def predict(twin: TwinFile, commands: np.ndarray) -> np.ndarray:
    """Where the twin's hand stops on the way to each face command (W, m; the examiner's radial stop) (discrepancy README §1)."""
    return reach_from_twin(twin).radial_stop(commands)


def sweep_predictions(twin: TwinFile, sweeps: list[MeasuredSweep], commands: dict) -> dict[str, np.ndarray]:
    """:func:`predict` for every sweep (trial id → predicted points, W, m) (discrepancy README §1)."""
    return {sw.trial_id: predict(twin, commands[sw.trial_id][0]) for sw in sweeps}
