"""The rules of spec §2.3 on a device's kinematic chain (E115, E116), checked for a device given in
device.json or inline in session.json (spec §4.3.2)."""

from __future__ import annotations

from haptify.codes import Code
from haptify.errors import Finding
from haptify.formats.session_format import Kinematics
from haptify.processing.kinematics import empty_joint_range, limit_order_violations


def kinematics_findings(kin: Kinematics, file: str, base: str) -> list[Finding]:
    """The rules of spec §2.3 on a DH chain, as findings located at ``file`` + ``base`` (a JSON pointer).

    E116: the joints are named ``q1 … qn`` in chain order, and a limit names only earlier joints.
    E115: every joint's range is non-empty — ``upper ≥ lower`` — at some configuration of the lattice of
    spec §8.3 step 1 (``RANGE_LATTICE_POINTS`` per joint, joint by joint within the earlier joints' coupled
    limits; :func:`haptify.processing.kinematics.empty_joint_range`); for constant limits simply ``upper ≥ lower``.
    It is the very lattice the modeled workspace samples, so a session that validates never fails
    ``workspace.modeled_volume`` for its limits.
    """
    out = [
        Finding(
            Code.KINEMATIC_CHAIN_INVALID,
            f"joint {i + 1} of the chain is named {joint.name!r}",
            file=file,
            pointer=f"{base}/joints/{i}/name",
            expected=f"q{i + 1}",
            found=joint.name,
        )
        for i, joint in enumerate(kin.joints)
        if joint.name != f"q{i + 1}"
    ]
    if out:
        return out
    names = [j.name for j in kin.joints]
    out = [
        Finding(
            Code.KINEMATIC_CHAIN_INVALID,
            f"the {side} limit of {names[i]} depends on {other}, which is not an earlier joint",
            file=file,
            pointer=f"{base}/joints/{i}/{side}/coefficients/{other}",
            expected=names[:i],
            found=other,
        )
        for i, side, other in limit_order_violations(kin)
    ]
    if out:
        return out
    empty = empty_joint_range(kin)
    if empty is not None:
        joint = kin.joints[empty.joint]
        out.append(
            Finding(
                Code.JOINT_LIMITS_EMPTY,
                f"the upper limit of {joint.name} lies below its lower limit (by at least "
                f"{-empty.widest_rad:.6g} rad) for every configuration of the earlier joints",
                file=file,
                pointer=f"{base}/joints/{empty.joint}",
                expected="upper ≥ lower for some configuration",
                found={"lower": joint.lower.model_dump(), "upper": joint.upper.model_dump()},
            )
        )
    return out
