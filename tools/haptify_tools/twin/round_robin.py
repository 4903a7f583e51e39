"""A simulated inter-laboratory round robin: N virtual labs measure the same device twin (TWIN.md, Round robins; spec §17.5.3).

Every lab has its own rig and its own examiner, drawn from the round robin's seed: the lab's handle F/T
calibration gain, its motion capture noise, its force plate (natural frequencies, and the corner gain and
mounting errors every simulated plate draws from its seed), the mass of its handle's connector, and an
examiner who performs the same protocols at their own pace and with their own random choices (press
depths, paths, timing).
How far the labs differ is set per property by :data:`SPREADS` (standard deviations, ``--lab-spread``).

``simulate_round_robin`` writes ``<out>/<lab>/`` (a dossier of :func:`~.simulate.simulate_dossier`:
``session/``, ``truth.json``, ``truth.npz``; the manifest's ``lab.id`` is the lab) per lab, and
``<out>/labs.json``: the spreads, and for each lab its seed, the rig it was given and the F/T gain of each
of its trials (the truth an inter-lab analysis of the labs' results should recover, ISO 5725-2; spec
§17.5.3, §19.6). Everything is a deterministic function of the twin, the options, the spreads and the seed.
"""

from __future__ import annotations

import json
import math
import os
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any, Callable

import numpy as np

from haptify.codes import Code
from haptify.errors import fail
from haptify.formats.storage import atomic_write_json
from haptify_tools.twin import rig as rg
from haptify_tools.twin.dossier_plan import SimulationOptions, name_number, plan
from haptify_tools.twin.dossier_trials import _slug
from haptify_tools.twin.model import TwinFile, set_param
from haptify_tools.twin.simulate import simulate_dossier
from haptify_tools.twin.truth_files import built_in_place


@dataclass(frozen=True)
class Spread:
    """One rig property that differs between labs: its default standard deviation and what it means."""

    default: float
    meaning: str


#: The properties that differ between labs, their default spreads and how a lab's value is drawn (z ~ N(0, 1)
#: per lab, independent per property; ``ft_gain_drift`` is the only one that varies within a lab).
SPREADS: dict[str, Spread] = {
    "ft_gain": Spread(
        0.01,
        "relative sd of the handle F/T sensor's calibration gain: the lab's whole F/T reading × (1 + sd·z) (RigConfig.ft_gain)",
    ),
    "ft_gain_drift": Spread(
        0.0,
        "relative sd of that gain's drift from trial to trial within a lab: each trial's "
        "reading × (1 + sd·z_trial) (RigConfig.ft_gain_drift_sd)",
    ),
    "mocap_noise": Spread(0.3, "log-sd of the lab's marker noise: nominal × exp(sd·z) (RigConfig.mocap_noise_m)"),
    "plate_modes": Spread(
        0.05,
        "relative sd of the force plate's natural frequencies, one z per axis: "
        "nominal × (1 + sd·z) (RigConfig.plate_modes_hz); the plate's corner gain and "
        "mounting errors are drawn from the lab's seed as for any simulated plate",
    ),
    "handle_mass": Spread(
        0.2, "relative sd of the handle connector's mass: nominal × max(0, 1 + sd·z) (twin handle.connector_mass.mass_kg)"
    ),
    "examiner_pace": Spread(
        0.1,
        "log-sd of the examiner's pace: their speeds × exp(sd·z) in free space, on the "
        "surface, in the presses and the figure eight (SimulationOptions.examiner_pace)",
    ),
}


def parse_spreads(items: list[str]) -> dict[str, float]:
    """``NAME=SD`` items (``--lab-spread``) over the defaults of :data:`SPREADS`; E903 for an unknown name or a
    negative or non-numeric sd."""
    out = {name: s.default for name, s in SPREADS.items()}
    for item in items:
        name, sd = name_number(item)
        if name not in SPREADS or not sd >= 0 or math.isinf(sd):
            raise fail(
                Code.USAGE,
                f"--lab-spread expects NAME=SD with a known property and SD ≥ 0, got {item!r}",
                expected=sorted(SPREADS),
                found=item,
            )
        out[name] = sd
    return out


@dataclass
class LabDraw:
    """One virtual lab: its id, the seed of its dossier, its rig, its handle connector mass (kg) and its
    examiner's pace."""

    lab: str
    seed: int
    rig: rg.RigConfig
    connector_mass_kg: float
    examiner_pace: float


def draw_labs(twin: TwinFile, base: rg.RigConfig, labs: int, seed: int, spreads: dict[str, float]) -> list[LabDraw]:
    """The ``labs`` virtual labs of a round robin (lab ids ``lab-01`` …): lab i's values come from its own
    generator ``SeedSequence([seed, i, 5725])``, so a lab is the same whatever the number of labs."""
    nominal_mass = float(twin.rig.connector_mass.mass_kg)
    out = []
    for i in range(1, labs + 1):
        ss = np.random.SeedSequence([int(seed) & 0xFFFFFFFF, i, 5725])
        rng = np.random.default_rng(ss)
        z = rng.standard_normal(7)
        f1, f2, f3 = (float(f * (1 + spreads["plate_modes"] * zk)) for f, zk in zip(base.plate_modes_hz, z[3:6]))
        rig = replace(
            base,
            ft_gain=float(base.ft_gain * (1 + spreads["ft_gain"] * z[0])),
            ft_gain_drift_sd=float(spreads["ft_gain_drift"]),
            mocap_noise_m=float(base.mocap_noise_m * math.exp(spreads["mocap_noise"] * z[1])),
            plate_modes_hz=(f1, f2, f3),
        )
        mass = nominal_mass * max(0.0, 1 + spreads["handle_mass"] * z[2])
        pace = math.exp(spreads["examiner_pace"] * z[6])
        out.append(LabDraw(f"lab-{i:02d}", int(ss.generate_state(1)[0]), rig, mass, pace))
    return out


@dataclass
class RoundRobinResult:
    """What :func:`simulate_round_robin` wrote: the output folder, ``labs.json`` and each lab's session."""

    out_dir: Path
    labs_json: Path
    sessions: dict[str, Path]


def simulate_round_robin(
    twin: TwinFile,
    out_dir: str | os.PathLike,
    options: SimulationOptions,
    labs: int,
    spreads: dict[str, float],
    *,
    overwrite: bool = False,
    advance: Callable[[int], object] | None = None,
) -> RoundRobinResult:
    """Simulate ``labs`` labs (≥ 2, E903) measuring ``twin`` with ``options`` (protocols, reps, durations; its
    rig is every lab's nominal rig, its seed the round robin's) into ``<out>/<lab>/`` and ``<out>/labs.json``.

    The folder is built beside the target and renamed into place (spec §3.6); E901 when it exists and not
    ``overwrite``. ``advance(n)`` is called after each simulated trial.
    """
    if labs < 2:
        raise fail(Code.USAGE, "a round robin needs at least two labs", expected=">= 2", found=labs)
    out = Path(out_dir)
    if out.exists() and not overwrite:
        raise fail(Code.OUTPUT_EXISTS, f"{str(out)!r} already exists", file=str(out))
    records: list[dict[str, Any]] = []  # labs.json's entries
    with built_in_place(out) as build:
        for lab in draw_labs(twin, options.rig, labs, options.seed, spreads):
            lab_twin = set_param(twin, "handle.connector_mass.mass_kg", lab.connector_mass_kg)
            opt = replace(
                options,
                seed=lab.seed,
                rig=lab.rig,
                lab_id=lab.lab,
                examiner_id=f"examiner-{lab.lab}",
                examiner_pace=lab.examiner_pace,
                session_id=f"rr-{_slug(twin.name)}-{lab.lab}",
            )
            simulate_dossier(lab_twin, build / lab.lab, opt, advance=advance)
            truth = json.loads((build / lab.lab / "truth.json").read_text())
            records.append(
                {
                    "lab": lab.lab,
                    "folder": lab.lab,
                    "session": f"{lab.lab}/session",
                    "seed": lab.seed,
                    "rig": {
                        "ft_gain": lab.rig.ft_gain,
                        "ft_gain_drift_sd": lab.rig.ft_gain_drift_sd,
                        "mocap_noise_m": lab.rig.mocap_noise_m,
                        "plate_modes_hz": list(lab.rig.plate_modes_hz),
                        "plate_corner_gains": truth["rig"]["plate_corner_gains"],
                        "plate_corner_positions_m": truth["rig"]["plate_corner_positions_m"],
                        "connector_mass_kg": lab.connector_mass_kg,
                    },
                    "examiner": {"id": f"examiner-{lab.lab}", "pace": lab.examiner_pace},
                    "trial_ft_gains": {t["id"]: t["ft_gain"] for t in truth["trials"] if "ft_gain" in t},
                }
            )
        doc = {
            "format": "haptify-round-robin",
            "version": "1.0",
            "twin": twin.name,
            "seed": options.seed,
            "reps": options.reps,
            "protocols": list(options.protocols),
            "labs": records,
            "spreads": spreads,
            "spread_meanings": {k: s.meaning for k, s in SPREADS.items()},
            "note": "each lab folder holds session/, truth.json and truth.npz (haptify simulate); the lab's F/T "
            "reading is the true one × trial_ft_gains[trial]",
        }
        atomic_write_json(build / "labs.json", doc)
    return RoundRobinResult(out, out / "labs.json", {r["lab"]: out / r["session"] for r in records})


def trial_count(options: SimulationOptions, labs: int) -> int:
    """Trials a round robin simulates (for a progress bar)."""
    return labs * len(plan(options))
