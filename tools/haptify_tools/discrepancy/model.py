"""``discrepancy.json``: the result of the discrepancy workflow (discrepancy README §4, "show").

Class path for the schema generator: ``haptify_tools.discrepancy.model.DiscrepancyFile``.
"""

from __future__ import annotations

from typing import Literal

from pydantic import BaseModel, ConfigDict, Field


#: the value sets of the file's enumerated fields, named for the code that fills them
PlaceKind = Literal["benchmark", "trial", "contact", "speed_band", "region"]
Channel = Literal["fx", "fy", "fz"]
ForceSource = Literal["measured", "twin before", "twin after"]
Verdict = Literal["explained", "unexplained residual", "no discrepancy"]
PathSource = Literal["motion capture + accelerometer", "motion capture"]


class _M(BaseModel):
    model_config = ConfigDict(extra="forbid")


class Place(_M):
    """One place where twin and measurement disagree: force residual RMS there in N and its share (0–1) of the residual energy (discrepancy README §1, §4)."""

    kind: PlaceKind
    label: str
    rms_before_N: float = Field(description="RMS of the force residual (all three axes) before, N.")
    rms_after_N: float = Field(description="The same with the updated twin, N.")
    energy_share_before: float = Field(description="Share of the whole residual energy (before) found here, 0–1.")
    samples: int


class _Estimate(_M):
    """A parameter's 95 % interval, and the per-drive values of an effect whose parameter holds one value per drive
    (discrepancy README §2, per drive; §3, uncertainty)."""

    ci95: list[float] | None = Field(
        default=None,
        description="95 % block-bootstrap interval of value [low, high] in unit (null "
        "when not estimable: a per-drive fit, or a search whose minimum is at the grid's end).",
    )
    per_drive: list[float] | None = Field(
        default=None,
        description="The values per drive axis when identified per drive "
        "(value is then their mean); null: one value shared by every drive.",
    )
    per_drive_stderr: list[float | None] | None = None
    per_drive_delta_bic: float | None = Field(
        default=None,
        description="ΔBIC of the per-drive values over the shared one (on "
        "the shared fit's residual, n − 1 extra parameters); null when not tried.",
    )


class CandidateFit(_Estimate):
    """A library effect fitted to one round's residual: value ± s.e. in ``unit``, ΔBIC, F-test p, validation and test shares, 0–1 (discrepancy README §2, §3)."""

    effect_id: str
    parameter: str
    value: float
    stderr: float | None = Field(description="Standard error of value (null when not estimable).")
    unit: str
    delta_bic: float
    p_value: float
    validation_improvement: float = Field(description="1 − RSS₁/RSS₀ on the validation blocks.")
    test_share: float = Field(description="Share of the test blocks' residual energy the effect explains.")
    simulations: int
    accepted: bool


class RoundResult(_M):
    """One round of the forward selection: the correlation lag D (rows), every candidate's fit and the near ties (discrepancy README §3)."""

    number: int
    decimation: int = Field(description="Rows kept every D-th sample for the statistics (correlation lag).")
    candidates: list[CandidateFit] = Field(description="Every fitted candidate, best ΔBIC first.")
    near_ties: list[str] = Field(
        default_factory=list, description="Other accepted candidates within 10 % of the best ΔBIC (ambiguous)."
    )


class AcceptedEffect(_Estimate):
    """An effect the workflow added to the twin, in the order it was accepted: value ± s.e. in ``unit``, ΔBIC, p, share explained 0–1 (discrepancy README §3, §4)."""

    order: int
    effect_id: str
    parameter: str
    value: float
    stderr: float | None
    unit: str
    delta_bic: float
    p_value: float
    share_explained: float = Field(description="Share of the held-out (test) residual energy it explained when added.")
    near_ties: list[str] = Field(default_factory=list)


class Structure(_M):
    """What is left after the last accepted effect (spec: 'no effect in the library explains this')."""

    heldout_share: float = Field(description="Share of held-out residual energy a generic state regression removes.")
    f_p_value: float
    ljung_box_p_value: float
    structured: bool


class SignalGap(_M):
    """Force residual RMS of one trial and axis, before and after, N; held-out = validation + test blocks (discrepancy README §3, §4)."""

    trial_id: str
    protocol: str
    channel: Channel
    rms_before_N: float
    rms_after_N: float
    heldout_rms_before_N: float
    heldout_rms_after_N: float


class BenchmarkGap(_M):
    """A benchmark computed by the reference's operator from the measured force and from the twin's force on the same path, in ``unit`` (discrepancy README §4)."""

    metric: str
    trial_id: str
    unit: str
    measured: float
    twin_before: float
    twin_after: float


class BenchmarkNotComputed(_M):
    """A benchmark the reference's operator could not compute on one trial's force, with the operator's code (discrepancy README §4)."""

    metrics: list[str] = Field(
        description="The benchmarks of the trial's protocol left out (one operator computes them together)."
    )
    trial_id: str
    force: ForceSource
    code: str = Field(description="The operator's error code (schemas/1.0/codes.json).")
    message: str


class ResidualCell(_M):
    """Where the residual left lives: one protocol × force axis, its held-out RMS about each trial's mean (N) and share of that energy."""

    protocol: str
    channel: Channel
    heldout_rms_N: float
    share: float


class StateShape(_M):
    """The residual against one state (discrepancy README §3, characterising the residual)."""

    state: str = Field(
        description="x, y, z (hand position, W, m), vx…vz, speed (m/s), ax…az (m/s²), q1…q3 (the twin's arm "
        "angles, rad) or time (s)."
    )
    kind: Literal["binned", "periodic"]
    heldout_r2: float = Field(description="1 − SSE/SSE of a constant per trial and axis, on the held-out rows (all axes).")
    description: str
    period: float | None = Field(default=None, description="Periodic shapes: the period, in the state's unit (m or rad).")
    amplitude_N: float | None = Field(default=None, description="Periodic shapes: the force amplitude, N (all axes).")
    amplitude_per_axis_N: list[float] = Field(default_factory=list)


class ResidualShape(_M):
    """What the residual left looks like: where it lives and which state it follows best (discrepancy README §3)."""

    where: list[ResidualCell]
    offset_share: float = Field(description="Share of the held-out residual energy a constant per trial and axis removes.")
    states: list[StateShape] = Field(description="Every state's best shape, the best first.")
    follows: str | None = Field(description="The state the residual follows best (null without rows to judge).")
    description: str
    structured: bool = Field(
        description="The best shape's held-out R² ≥ 0.25, or the constant removes ≥ 25 % (it counts "
        "in the verdict when the gap is above the floor's median)."
    )


class WorkspaceRegion(_M):
    """Position residual RMS of the workspace sweep in one region (tertiles of the sweep per world axis), m (discrepancy README §1, §4)."""

    label: str
    rms_before_m: float
    rms_after_m: float
    samples: int


class WorkspaceGap(_M):
    """The workspace sweep against the twin's examiner rule (radial stop), before and after, m and m³ (discrepancy README §1, §4)."""

    trial_id: str
    rms_before_m: float = Field(description="RMS distance measured − predicted sweep point, before, m.")
    rms_after_m: float
    measured_volume_m3: float = Field(description="The reference's volume operator (spec §8.4) on the measured points.")
    twin_before_volume_m3: float = Field(description="The same operator on the twin's predicted points, before.")
    twin_after_volume_m3: float
    regions: list[WorkspaceRegion] = Field(description="Regions ranked by residual RMS before (largest first).")


class DiscrepancyFile(_M):
    """The whole result of ``haptify discrepancy`` (discrepancy README §4)."""

    format: Literal["haptify-discrepancy"] = "haptify-discrepancy"
    version: Literal["1.0"] = "1.0"
    session_id: str
    twin_name: str
    verdict: Verdict = Field(
        description="explained: effects accepted, no structure left and the held-out gap not significantly above the "
        "floor; unexplained residual: structure left, or a held-out gap significantly above the floor, that "
        "no library effect explains (see `residual`); no discrepancy: nothing accepted, no structure left "
        "and the gap not significantly above the floor."
    )
    accepted: list[AcceptedEffect]
    rounds: list[RoundResult]
    structure: Structure
    where: list[Place] = Field(description="Places ranked by residual RMS before (largest first).")
    signal_gaps: list[SignalGap]
    benchmark_gaps: list[BenchmarkGap]
    workspace_gaps: list[WorkspaceGap] = Field(default_factory=list)
    heldout_gap_before_N: float = Field(description="RMS force residual on the held-out blocks, all trials, before.")
    heldout_gap_after_N: float
    floor_N: float | None = Field(
        default=None,
        description="The floor: the one-sided 95 % upper prediction bound of the held-out "
        "gap the updated twin leaves against replays of the session's force protocols that it "
        "generated itself through the virtual rig (the method's resolution: path reconstruction "
        "and sensor noise), from floor_replays_N; null when no trial can be replayed.",
    )
    heldout_gap_above_floor_before_N: float | None = Field(default=None, description="√max(gap² − floor², 0) before (N).")
    heldout_gap_above_floor_after_N: float | None = Field(default=None, description="√max(gap² − floor², 0) after (N).")
    floor_replays_N: list[float] = Field(
        default_factory=list, description="The held-out gap of each replay the floor is made from (seeds 0, 1, …), N."
    )
    floor_median_N: float | None = None
    gap_p_value: float | None = Field(
        default=None,
        description="One-sided p-value of 'the held-out gap after is one more draw "
        "of the floor' (Student-t predictive test on the replays' log gaps).",
    )
    gap_significant: bool | None = Field(default=None, description="gap_p_value < 0.05, i.e. the gap after is above floor_N.")
    residual: ResidualShape | None = Field(
        default=None,
        description="The residual left, characterised (always computed; it "
        "is what an 'unexplained residual' verdict reports instead of an effect).",
    )
    benchmarks_not_computed: list[BenchmarkNotComputed] = Field(default_factory=list)
    not_observable: dict[str, str] = Field(description="Library effect ids the force residual cannot reveal, and why.")
    hand_path: dict[str, PathSource] = Field(
        default_factory=dict,
        description="Per force trial id, what the path driving the twin came from: motion "
        "capture below the crossover and the handle accelerometer above it, or motion capture alone (no "
        "handle_accel stream, or more than half of the trial's rows near readings at the accelerometer's range).",
    )
    settings: dict[str, float] = Field(
        description="The workflow's constants, each named with its unit (_hz, _s, _rad; "
        "the statistics' thresholds are plain numbers): the hand path's filters and "
        "margins, the replay's rest detection, the residual's low-pass and simulation "
        "rate, the acceptance thresholds (discrepancy README)."
    )
    files: dict[str, str] = Field(default_factory=dict, description="Outputs written beside this file.")

    def gap_summary(self) -> str:
        """One line: the held-out force gap before → after (N), and the same above the floor when known."""
        text = f"held-out force gap {self.heldout_gap_before_N:.4g} N → {self.heldout_gap_after_N:.4g} N"
        if self.floor_N is not None:
            text += (
                f" (floor {self.floor_N:.4g} N; above it {self.heldout_gap_above_floor_before_N:.4g} N → "
                f"{self.heldout_gap_above_floor_after_N:.4g} N)"
            )
        return text
