"""What a simulated dossier holds and in which order (design §4): the device protocols and rig trials, their
default durations, :class:`SimulationOptions`, the planned trials on the session clock (:func:`plan`) and
each trial's seeded generators and F/T gain, drawn from ``(seed, crc32(trial id))`` so a trial is the same
whichever other protocols are simulated with it."""

from __future__ import annotations

import math
import zlib
from dataclasses import dataclass, field

import numpy as np

from haptify.codes import Code
from haptify.errors import fail

from haptify_tools.twin import examiner as ex
from haptify_tools.twin import hand_path, plate_loads
from haptify_tools.twin import rig as rg


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
        raise fail(
            Code.USAGE, f"unknown protocol(s) {bad or text!r}", expected=["all", *DEVICE_PROTOCOLS, *RIG_TRIALS], found=text
        )
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


def _paced(periods_s: tuple[float, float], pace: float) -> tuple[float, float]:
    """A protocol's first and last period (s) at the examiner's ``pace`` (periods ÷ it)."""
    return periods_s[0] / pace, periods_s[1] / pace
