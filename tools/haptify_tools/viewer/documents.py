"""The markdown documents of the viewer recording: ``/results`` (a results file's metrics, spec §15.2)
and ``/session`` (the session, the compared one, and how to read the 3-D view)."""

from __future__ import annotations

from collections.abc import Collection
from typing import TYPE_CHECKING, Any

from haptify.formats.storage import SessionFolder
from haptify_tools.viewer.plan import COMPACT_RATE_HZ, HAND_FORCE_M_PER_N, PLATE_FORCE_M_PER_N, TrialPlan

if TYPE_CHECKING:  # imported where used: a raw-only recording needs neither (start-up time)
    from haptify.pipeline.results import ResultsFile


def _cell(text: Any) -> str:
    return str(text).replace("|", "\\|").replace("\n", " ")


def _num(v: Any) -> str:
    if v is None:
        return ""
    if isinstance(v, list):
        return "[" + ", ".join(_num(x) for x in v) + "]"
    return f"{v:.4g}"


def results_markdown(results: ResultsFile, session_id: str) -> str:
    """The metrics of a results file as markdown tables (spec §15.2)."""
    lines = [
        f"# Results — session `{results.session_id}`",
        f"{results.implementation.name} {results.implementation.version}, spec {results.spec_version}",
        "",
    ]
    if results.session_id != session_id:
        lines += [f"**Warning:** these results are for session `{results.session_id}`, not `{session_id}`.", ""]
    lines += ["| metric | value | unit | n | sd | trials | warnings |", "|---|---:|---|---:|---:|---|---|"]
    for m in results.metrics:
        lines.append(
            f"| {_cell(m.id)} | {_num(m.value)} | {_cell(m.unit)} | {m.n} | {_num(m.sd)} | "
            f"{_cell(', '.join(m.trials))} | {_cell(', '.join(m.warnings))} |"
        )
    if results.unavailable:
        lines += ["", "## Unavailable", "", "| metric | code | reason |", "|---|---|---|"]
        lines += [f"| {_cell(u.id)} | {u.code} | {_cell(u.reason)} |" for u in results.unavailable]
    if results.warnings:
        lines += ["", "## Warnings", "", "| code | metric | trial | message |", "|---|---|---|---|"]
        lines += [
            f"| {w.code} | {_cell(w.metric or '')} | {_cell(w.trial or '')} | {_cell(w.message)} |" for w in results.warnings
        ]
    return "\n".join(lines) + "\n"


def session_markdown(
    session: SessionFolder,
    trials: list[TrialPlan],
    other: SessionFolder | None,
    notes: Collection[str] = (),
    derived: str = "full",
) -> str:
    """A summary of the session (and the compared one) and how to read the 3-D view."""
    m = session.manifest
    dev = session.device()
    lines = [
        f"# Session `{m.session_id}`",
        "",
        f"{dev.manufacturer} {dev.model} · {m.date} · lab `{m.lab.id}` · examiner `{m.examiner.id}`",
        "",
    ]
    if other is not None:
        od = other.device()
        lines += [
            f"Compared with session `{other.session_id}` ({od.manufacturer} {od.model}), drawn in lighter colours "
            "under the `compare` entities.",
            "",
        ]
    lines += ["| trial | protocol | powered | streams | compared with |", "|---|---|---|---|---|"]
    for tp in trials:
        t = tp.trial
        kinds = ", ".join(f"{s.kind} ({s.rows} @ {s.rate_hz:g} Hz)" for s in t.streams)
        lines.append(
            f"| {_cell(t.id)} | {t.protocol} | {'yes' if t.powered else 'no'} | {_cell(kinds)} | "
            f"{_cell(tp.counterpart.get('compare', '—' if other is not None else ''))} |"
        )
    lines += ["", "World frame W: origin at the centre of the plate's top surface, z up, right-handed (spec §1.2)."]
    if derived == "off":
        lines.append(
            "Derived signals (calibrated hand force, plate force and COP, DFT321, contact signals, force arrows, "
            "workspace meshes) are not recorded: `haptify view --derived compact` or `--derived full` adds them."
        )
    else:
        from haptify.metrics import free_space

        lines += [
            f"Arrows: hand force {HAND_FORCE_M_PER_N * 100:g} cm per N; plate force {PLATE_FORCE_M_PER_N * 100:g} cm per N.",
            f"Free-space force field: mean hand force per {free_space.PARAMETERS.force_field_bin_m * 100:g} cm bin "
            f"holding at least {free_space.PARAMETERS.force_field_min_samples} samples (spec §9.5).",
            "The plate arrow is the force the load exerts on the plate, drawn with its head at the COP.",
        ]
        if derived == "compact":
            lines.append(
                f"Derived signals are compact: float32, at most {COMPACT_RATE_HZ:g} Hz (faster time series as a "
                "min/max envelope, faster arrows point-sampled); `--derived full` records every sample."
            )
    if notes:
        lines += ["", "## Not shown", ""] + [f"- {_cell(n)}" for n in notes]
    return "\n".join(lines) + "\n"
