"""The frictionless-surface fixtures and cases (spec chapter 12): planar forces of known magnitude during
rendered contact on tilted planes (§12.2)."""

from __future__ import annotations

import numpy as np

from haptify.metrics import surface
from haptify_tools.conformance_fixtures.records import Fixture, case
from haptify_tools.conformance_fixtures.truth import Fn, active_session, grid, pair_step


def tangent_basis(n: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    u = np.cross(n, [1.0, 0.0, 0.0])
    u /= np.linalg.norm(u)
    return u, np.cross(n, u)


def surface_fixture(
    name: str,
    fmt: str,
    rig_kind: str,
    normal_raw,
    point,
    contacts,
    secs: float,
    planar: Fn,
    rates,
    desc: str,
    preload: float,
    outside: float | None = 2.0,
) -> Fixture:
    """A frictionless-surface fixture (spec §12.2): a hand circling on the rendered plane (normal ``normal_raw``
    through ``point``) in contact during ``contacts`` (s), feeling ``planar(t)`` N against its motion and 1.5 N
    along the normal; outside contact ``outside`` N planar (None: ``planar``) and ``preload`` N along the normal.
    Its cases are the planar force's mean and SD over the guarded contact rows."""
    guard = surface.PARAMETERS.contact_guard_s
    n = np.asarray(normal_raw, float) / np.linalg.norm(normal_raw)
    u, v = tangent_basis(n)
    pp = np.asarray(point, float)

    def contact(t, contacts=contacts):
        return np.any([(t >= on) & (t <= off) for on, off in contacts], axis=0)

    def position(t, u=u, v=v, n=n, pp=pp, contact=contact):
        depth = np.where(contact(t), 0.002, -0.01)
        return pp + 0.03 * (np.cos(2 * t)[:, None] * u + np.sin(2 * t)[:, None] * v) - depth[:, None] * n

    def force(t, u=u, v=v, n=n, contact=contact, planar=planar, outside=outside, preload=preload):
        d = np.sin(2 * t)[:, None] * u - np.cos(2 * t)[:, None] * v
        mag = np.where(contact(t), planar(t), outside if outside is not None else planar(t))
        return mag[:, None] * d + np.where(contact(t), 1.5, preload)[:, None] * n

    def commanded(t, n=n, contact=contact):
        return np.where(contact(t), 1.5, 0.0)[:, None] * n

    rendering = {"surface_point_m": list(point), "surface_normal": [float(c) for c in n], "stiffness_N_per_m": 750.0}

    fx = Fixture(
        name,
        active_session(
            name, rig_kind, "surface-1", "frictionless_surface", secs, 0.05, position, force, commanded, rendering, rates, fmt
        ),
    )
    tg = grid(secs)
    used = np.any([(tg >= on + guard - 1e-9) & (tg <= off - guard + 1e-9) for on, off in contacts], axis=0)
    truth = planar(tg[used])
    if preload:  # the low-passed steps of the planar force still ring a little beyond the guard: superpose them
        fs, step = rates[0], planar(tg[used]) - outside
        truth = outside + step * sum(
            pair_step(tg[used] - on, fs) - pair_step(tg[used] - off - 1 / fs, fs) for on, off in contacts
        )
    short = name.removeprefix("surf-")
    spans = " and ".join(f"from {on} s to {off} s" for on, off in contacts)
    how = (
        f"planar force of the stated magnitude against the motion plus 1.5 N along the normal {normal_raw}, in contact "
        f"{spans} (commanded normal force 1.5 N), statistics over the 100 Hz grid rows inside the "
        f"contact minus the {guard} s guard at both ends (spec §12.2)"
    )
    if preload:
        how += (
            f"; outside contact the hand feels {outside} N planar and {preload} N along the normal while the "
            "commanded force is zero: contact is the COMMANDED force's (§12.2), so those rows never count. The "
            "planar force steps at each transition; the values superpose the zero-phase low-pass's step response "
            "(§7.2, 20 Hz at 1 kHz), whose ringing beyond the 50 ms guard moves them by up to 0.3 %; the hand "
            "direction turns 0.1 rad within the filter's span, a second-order effect"
        )
    fx.cases += [
        case(
            f"surface.planar_force_mean.{short}",
            "surface.planar_force_mean",
            "12.2",
            name,
            truth.mean(),
            "N",
            "analytic",
            how,
            desc,
        ),
        case(
            f"surface.planar_force_sd.{short}",
            "surface.planar_force_sd",
            "12.2",
            name,
            truth.std(ddof=1) if len(truth) > 1 else 0.0,
            "N",
            "analytic",
            how,
            desc,
        ),
    ]
    return fx


def surface_fixtures() -> list[Fixture]:
    # name, format, rig, normal, plane point, contact intervals (s), duration, planar force in contact, rates, description,
    # measured normal force outside contact (N: the device's own weight pushing the hand up)
    variants = [
        (
            "surf-typical",
            "parquet",
            "example",
            [0.0, 0.0, 1.0],
            (0.0, 0.05, 0.10),
            ((1.0, 9.0),),
            10.0,
            lambda t: 0.53 + 0.1 * np.sin(2 * np.pi * 0.5 * t),
            (1000.0, 500.0, 100.0),
            "Typical: a horizontal surface.",
            0.0,
        ),
        (
            "surf-tilted-rotated-csv",
            "csv",
            "rotated",
            [0.0, 0.2, 1.0],
            (0.0, 0.05, 0.12),
            ((1.5, 8.5),),
            10.0,
            lambda t: 0.4 + 0.15 * np.cos(2 * np.pi * 0.25 * t),
            (400.0, 250.0, 150.0),
            "Tricky: a tilted surface normal, rotated sensor frames, CSV, unusual rates.",
            0.0,
        ),
        (
            "surf-constant",
            "parquet",
            "example",
            [0.3, 0.0, 1.0],
            (0.01, 0.0, 0.10),
            ((0.8, 5.2),),
            6.0,
            lambda t: 0.25 + 0 * t,
            (1000.0, 500.0, 100.0),
            "Edge: a constant planar force (SD 0), short trial.",
            0.0,
        ),
        (
            "surf-preload",
            "parquet",
            "example",
            [0.0, 0.0, 1.0],
            (0.0, 0.02, 0.11),
            ((0.8, 1.8), (2.4, 3.4), (4.0, 5.0), (5.6, 6.6)),
            7.4,
            lambda t: 0.3 + 0 * t,
            (1000.0, 500.0, 100.0),
            "Tricky: four short contacts, and outside them the device's uncompensated weight pushes the hand up 0.5 N along "
            "the normal (a measured-force contact rule counts those samples; the guard matters at eight transitions).",
            0.5,
        ),
    ]
    return [surface_fixture(*v, outside=None if v[0] == "surf-constant" else 2.0) for v in variants]
