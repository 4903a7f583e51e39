"""What the virtual examiner knows about the device's reach (design §4): the joint-limit box in unit
coordinates mapped through the coupled limits (reference ``configurations_from_unit``), forward and inverse
kinematics into W and the base-collision clearance, built from a DH chain or from a twin's TRUE kinematics."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np

from haptify.formats.conventions import (
    quat_to_matrix,
)


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
    from haptify.processing.kinematics import configurations_from_unit, forward_positions
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
