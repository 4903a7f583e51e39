"""Tolerance budgets of the conformance cases (spec §16.2, §16.7): where each case's tolerance comes from.

A budget is a list of terms, each a source of difference between a correct implementation's answer and
the expected value known by construction — numerical precision, the bias an operator is specified to have,
the noise the fixture was generated with. The case's tolerance is the sum of its terms (absolute parts in
the metric's unit, relative parts dimensionless); ``haptify-conform --lint`` flags a case whose tolerance
is looser than its budget. Patterns are matched against case ids in order, first match wins.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from fnmatch import fnmatchcase


@dataclass(frozen=True)
class Term:
    """One source of allowed difference: ``abs`` in the metric's unit, ``rel`` relative to the expected value."""

    source: str
    abs: float = 0.0
    rel: float = 0.0


FLOAT = Term("float64 rounding (filters, FFTs and sums over ≤ 10⁵ samples)", rel=1e-6)
OPERATOR_BIAS = Term("the volume operator's boundary bias (spec §8.8: within 0.5 %)", rel=5e-3)
COARSE_MODEL = Term("voxels 2.2× coarser relative to the 0.45-scale model than to a full-size one", rel=2.5e-3)
TWO_SOLIDS_REL = Term("both solids' boundary biases (spec §8.8: 0.5 % each)", rel=1e-2)
TWO_SOLIDS = Term("both solids' boundary biases (spec §8.8: 0.5 % each)", abs=1e-2)
LOWPASS_ENDS = Term("the zero-phase low-pass's end effects and the calibration's rounding under rotation", rel=5e-4)
STIFFNESS_FIT = Term(
    "penetration (10 Hz) and force (20 Hz) low-passed differently along the rise (≤ 1 % on these presses)", rel=1.5e-2
)
PEAK_FILTER = Term("the 20 Hz low-pass rounds a press's peak and its plateau (≤ 0.7 % on these presses)", rel=1e-2)

REPS_U = Term(
    "each repetition's mean |F| within the low-pass end effects (5e-4 of x): |Δu| ≤ (|Δx₁| + |Δx₂|)/2 = 1.05 % of u = 0.05·x₁",
    rel=1.05e-2,
)

BUDGETS: list[tuple[str, tuple[Term, ...]]] = [
    ("*.uncertainty-u.two-reps", (REPS_U,)),
    ("*.uncertainty-expanded.two-reps", (REPS_U, Term("Student's t quantile to 6 digits", rel=1e-6))),
    ("*.uncertainty-k.*", (Term("Student's t quantile to 6 digits", rel=1e-6),)),
    ("workspace.spec_box_volume.*", (Term("float64 product of three edges", abs=1e-12, rel=1e-9),)),
    (
        "workspace.measured_volume.capless",
        (OPERATOR_BIAS, Term("the dent without boundary samples is resolved on the coarse lattice only (≤ 0.2 %)", rel=2e-3)),
    ),
    (
        "workspace.measured_volume.thin-slab",
        (
            OPERATOR_BIAS,
            Term(
                "a slab only twice the operator's resolution limit (2 h) thick: both faces' sub-voxel ramps overlap", rel=1.5e-2
            ),
        ),
    ),
    (
        "workspace.measured_volume.two-lobes",
        (OPERATOR_BIAS, Term("the closing's fillet in the lobes' crease (spec §8.8)", rel=5e-3)),
    ),
    (
        "workspace.measured_volume.occlusion-repaired",
        (
            OPERATOR_BIAS,
            Term(
                "the strips between the donors and the trial's own samples are bridged on the coarse lattice only (≤ 0.2 %)",
                rel=2e-3,
            ),
        ),
    ),
    ("workspace.measured_volume.*", (OPERATOR_BIAS,)),
    ("workspace.modeled_volume.*", (OPERATOR_BIAS, COARSE_MODEL)),
    ("workspace.volume_ratio.ball-outside", (TWO_SOLIDS_REL,)),
    ("workspace.volume_ratio.ball", (TWO_SOLIDS_REL,)),
    ("workspace.coverage.ball", (TWO_SOLIDS_REL,)),
    ("workspace.volume_ratio.*", (TWO_SOLIDS,)),
    ("workspace.coverage.*", (TWO_SOLIDS,)),
    (
        "free_space.*.glimpse",
        (Term("a force linear in time passes the §7.2 low-pass exactly (chord removed): rounding only", rel=1e-4),),
    ),
    ("free_space.force_sd.constant", (Term("the calibration's rounding under rotation", abs=1e-4),)),
    ("free_space.force_sd.jitter", (Term("the calibration's rounding under rotation", abs=1e-4),)),
    (
        "free_space.angular_speed_mean.jitter",
        (Term("jitter about the vertical turns the spin axis: |ω| changes to second order", rel=1e-3),),
    ),
    ("free_space.force_sd.*", (Term("the low-pass's end effects on the spread of the magnitudes", rel=1e-3),)),
    ("free_space.force_*", (LOWPASS_ENDS,)),
    ("free_space.plate_force_mean.*", (Term("the low-pass's end effects on the plate stream", rel=1e-4),)),
    (
        "free_space.speed_mean.*",
        (Term("central differences on a circle, (ωΔt)²/6 ≤ 5e-5, and the 10 Hz low-pass at the segments' ends", rel=5e-4),),
    ),
    ("free_space.angular_speed_mean.*", (FLOAT,)),
    ("surface.planar_force_sd.constant", (Term("the calibration's rounding under rotation", abs=1e-4),)),
    (
        "surface.planar_force_sd.preload",
        (
            Term(
                "the low-pass's step response ringing past the 50 ms guard at eight contact "
                "transitions (0.3 % on the mean, twice that on the spread)",
                rel=1e-2,
            ),
        ),
    ),
    ("surface.planar_force_mean.*", (Term("the 20 Hz low-pass's smear at the guarded contact edges", rel=1e-3),)),
    ("surface.planar_force_sd.*", (Term("the 20 Hz low-pass's smear at the guarded contact edges", rel=3e-3),)),
    (
        "vibration.*.bursts",
        (
            Term(
                "the analysed signal known to ~1e-6 of its amplitude (the start-up transient decayed to "
                "e^−12, the bursts' spectra within a few Hz of their tones)",
                rel=1e-4,
            ),
        ),
    ),
    ("vibration.*.near-cutoff-csv", (FLOAT, Term("the start-up transient of a 12 Hz tone left after the 0.5 s trim", rel=2e-4))),
    ("vibration.*", (FLOAT,)),
    ("stiffness.peak_force.*", (PEAK_FILTER,)),
    ("stiffness.*", (STIFFNESS_FIT,)),
    ("rig.plate_natural_frequency.clean", (Term("exact inputs: rounding of the FFT and the parabola", abs=1e-4),)),
    (
        "rig.plate_natural_frequency.*",
        (
            Term("the zero-padded FFT bin of the 0.5 s window", abs=0.24),
            Term("the parabola's vertex bias on a damped peak and 0.01 N noise", abs=0.36),
        ),
    ),
    (
        "rig.cop_error.*",
        (
            Term(
                "5 mN noise per channel: the mean of three placements' COP errors scatters with sd 3.6e-5 m about "
                "the drawn offsets' (1 300 registry-challenge rig sessions, largest 1.7e-4 m; "
                "benchmarks/bench_cop_error_spread.py); 5.4 sd",
                abs=2e-4,
            ),
        ),
    ),
    ("rig.sync_offset.*", (Term("a third of the 1 ms step of the lag search", abs=3e-4),)),
    ("rig.handle_calibration_rms.quiet", (Term("the filters' end effects on the tumbling gravity", abs=2e-4),)),
    ("rig.handle_calibration_rms.*", (Term("sampling spread of an RMS over a few hundred independent samples", rel=0.15),)),
    (
        "rig.handle_force_offset_u.quiet",
        (Term("the filters' end effects on the tumbling gravity, averaged by the fit", abs=2e-5),),
    ),
    (
        "rig.handle_force_offset_u.*",
        (
            Term(
                "sampling spread of a batch-means covariance over 20 blocks: 1/√38 = 16 % on "
                "each axis's u, three standard deviations",
                rel=0.5,
            ),
        ),
    ),
    (
        "dynamics.torque_rmse*.fit-quality",
        (Term("no torque about the gimbal centre and no torque noise: a fitted model's residual torque", abs=2e-3),),
    ),
    ("dynamics.*.fit-quality", (Term("the raw force noise σ that a fitted model cannot remove (spec §11.4.5)", abs=1e-2),)),
    ("dynamics.torque_rmse*.predict*", (Term("float64 rounding of the H-W simulation", abs=1e-8, rel=1e-7),)),
    ("dynamics.error_vs_distance.*", (Term("float64 rounding of the distances and the least-squares line", abs=1e-6, rel=1e-6),)),
    ("dynamics.*", (Term("float64 rounding of the H-W simulation", abs=1e-7, rel=1e-7),)),
]


def budget_for(case_id: str) -> tuple[Term, ...]:
    """The budget of a case id (first matching pattern); KeyError when no pattern matches."""
    for pattern, terms in BUDGETS:
        if fnmatchcase(case_id, pattern):
            return terms
    raise KeyError(f"no tolerance budget matches case {case_id!r}: add one to haptify_tools.tolerance_budgets")


def budget_record(case_id: str) -> list[dict]:
    """The budget as the case file stores it (``provenance.budget``)."""
    return [asdict(t) for t in budget_for(case_id)]
