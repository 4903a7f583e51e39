"""``report.html`` of the discrepancy workflow with its figures (discrepancy README §4, "show").

Figures (PNG beside the page): residual before/after against speed and height, the residual over the
workspace (x–z projection) before/after, the stiffness curves (normal force against penetration)
measured/before/after, and each trial's force measured/before/after.
"""

from __future__ import annotations

import html
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from haptify.formats.storage import atomic_write_text
from haptify_tools.discrepancy.data import MeasuredTrial
from haptify_tools.discrepancy.identify import Selection
from haptify_tools.discrepancy.model import DiscrepancyFile

if TYPE_CHECKING:  # matplotlib is imported when figures are drawn
    from matplotlib.figure import Figure


def _figures(trials: list[MeasuredTrial], sel: Selection) -> list[tuple[str, str, Figure]]:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    before, after = sel.initial_sim, sel.final_sim
    figs: list[tuple[str, str, Figure]] = []
    pieces: dict[str, list[np.ndarray]] = {k: [] for k in ("speed", "z", "x", "rb", "ra")}
    for tr in trials:
        v = tr.valid
        pieces["speed"].append(tr.speed[v])
        pieces["x"].append(tr.position[v, 0])
        pieces["z"].append(tr.position[v, 2])
        pieces["rb"].append(np.linalg.norm(tr.force - before[tr.trial_id], axis=1)[v])
        pieces["ra"].append(np.linalg.norm(tr.force - after[tr.trial_id], axis=1)[v])
    if sel.sweeps is not None:
        fig, axes = plt.subplots(1, 3, figsize=(13, 4), sharex=True, sharey=True)
        for ax, (title, pts) in zip(
            axes, (("measured sweep", None), ("twin before", sel.initial_sweep), ("twin after", sel.final_sweep))
        ):
            for sw in sel.sweeps.items:
                p = sw.position if pts is None else pts[sw.trial_id]
                ax.plot(p[sw.valid, 0], p[sw.valid, 2], ".", ms=1.5, color="k" if pts is None else "C0")
            ax.set_title(title)
            ax.set_xlabel("x (m)")
            ax.set_aspect("equal")
        axes[0].set_ylabel("z (m)")
        figs.append(
            (
                "workspace_before_after",
                "Workspace (x–z projection): the measured sweep and the twin's sweep "
                "(examiner's radial stop toward the same commands) before and after.",
                fig,
            )
        )
    if not trials:
        return figs
    res = {k: np.concatenate(v) for k, v in pieces.items()}
    fig, axes = plt.subplots(1, 2, figsize=(10, 3.8))
    for ax, key, label in ((axes[0], "speed", "handle speed (m/s)"), (axes[1], "z", "height z (m)")):
        ax.plot(res[key], res["rb"], ".", ms=2, alpha=0.4, label="before")
        ax.plot(res[key], res["ra"], ".", ms=2, alpha=0.4, label="after")
        ax.set_xlabel(label)
        ax.set_ylabel("|force residual| (N)")
        ax.legend()
    figs.append(("residual_vs_state", "Force residual magnitude against the state, before and after the update.", fig))
    fig, axes = plt.subplots(1, 2, figsize=(10, 4), sharex=True, sharey=True)
    top = max(float(np.quantile(res["rb"], 0.99)), 1e-9)
    for ax, key, title in ((axes[0], "rb", "before"), (axes[1], "ra", "after")):
        sc = ax.scatter(res["x"], res["z"], c=res[key], s=2, vmin=0, vmax=top, cmap="viridis")
        ax.set_title(f"|residual| over the workspace, {title}")
        ax.set_xlabel("x (m)")
        ax.set_ylabel("z (m)")
        ax.set_aspect("equal")
    fig.colorbar(sc, ax=axes, label="N")
    figs.append(
        (
            "workspace_residual",
            "Where in the workspace (x–z projection of the measured path) the residual lives, before and after.",
            fig,
        )
    )
    stiff = [tr for tr in trials if tr.active and tr.protocol == "stiffness"]
    if stiff:
        fig, ax = plt.subplots(figsize=(6, 4))
        for i, tr in enumerate(stiff):
            pen, n = tr.penetration()
            c = tr.valid & tr.contact
            lab = (lambda s: s) if i == 0 else (lambda s: None)
            ax.plot(1000 * pen[c], (tr.force @ n)[c], "k.", ms=2, label=lab("measured"))
            ax.plot(1000 * pen[c], (before[tr.trial_id] @ n)[c], "C0.", ms=2, label=lab("twin before"))
            ax.plot(1000 * pen[c], (after[tr.trial_id] @ n)[c], "C1.", ms=2, label=lab("twin after"))
        ax.set_xlabel("penetration (mm)")
        ax.set_ylabel("normal force (N)")
        ax.legend()
        figs.append(("stiffness_curves", "Stiffness curves: normal force against penetration in contact.", fig))
    for tr in trials[:6]:
        fig, axes = plt.subplots(3, 1, figsize=(10, 5), sharex=True)
        for k, ax in enumerate(axes):
            ax.plot(tr.t, tr.force[:, k], "k", lw=0.8, label="measured")
            ax.plot(tr.t, before[tr.trial_id][:, k], "C0", lw=0.8, label="twin before")
            ax.plot(tr.t, after[tr.trial_id][:, k], "C1", lw=0.8, label="twin after")
            ax.set_ylabel(f"F{'xyz'[k]} (N)")
        axes[0].legend(loc="upper right")
        axes[-1].set_xlabel("time (s)")
        figs.append((f"force_{tr.trial_id}", f"Trial {tr.trial_id} ({tr.protocol}): hand force measured and simulated.", fig))
    return figs


def _table(head: list[str], rows: list[list[object]]) -> str:
    def cell(v):
        return f"{v:.4g}" if isinstance(v, float) else html.escape(str(v))

    return (
        "<table><thead><tr>"
        + "".join(f"<th>{html.escape(h)}</th>" for h in head)
        + "</tr></thead><tbody>"
        + "".join("<tr>" + "".join(f"<td>{cell(v)}</td>" for v in r) + "</tr>" for r in rows)
        + "</tbody></table>"
    )


def write_figures(folder: Path, trials: list[MeasuredTrial], sel: Selection) -> list[tuple[str, str]]:
    """Draw the report's PNG figures (forces in N, positions in m) into ``folder``; returns (file stem, caption) per figure (discrepancy README §4)."""
    import matplotlib.pyplot as plt

    out = []
    for name, caption, fig in _figures(trials, sel):
        fig.savefig(folder / f"{name}.png", dpi=90, bbox_inches="tight")
        plt.close(fig)
        out.append((name, caption))
    return out


def _residual_html(result: DiscrepancyFile) -> str:
    """The gap test and the residual's description (discrepancy README §3)."""
    out = ""
    if result.gap_p_value is not None:
        out += (
            f"<p>Held-out gap after {result.heldout_gap_after_N:.4g} N against the floor's 95 % bound "
            f"{result.floor_N:.4g} N (replays: {', '.join(f'{g:.3g}' for g in result.floor_replays_N)} N): p = "
            f"{result.gap_p_value:.2g} → {'significantly above the floor' if result.gap_significant else 'within the floor'}.</p>"
        )
    r = result.residual
    if r is not None:
        out += (
            f"<p>The residual left: {html.escape(r.description)}.</p>"
            + _table(["state", "shape", "held-out R²"], [[x.state, x.kind, x.heldout_r2] for x in r.states[:6]])
            + _table(
                ["protocol", "axis", "held-out RMS (N)", "share"],
                [[c.protocol, c.channel, c.heldout_rms_N, c.share] for c in r.where],
            )
        )
    if result.benchmarks_not_computed:
        out += (
            "<p>Benchmarks not computed: "
            + "; ".join(
                html.escape(f"{', '.join(b.metrics)} on {b.trial_id} ({b.force}): {b.code}")
                for b in result.benchmarks_not_computed
            )
            + "</p>"
        )
    return out


def write_report(folder: Path, result: DiscrepancyFile, figs: list[tuple[str, str]]) -> dict[str, str]:
    """Write ``report.html`` into ``folder`` beside the figures :func:`write_figures` drew there; returns the file map for ``files`` (discrepancy README §4)."""
    acc = _table(
        ["#", "effect", "parameter", "value", "s.e.", "unit", "ΔBIC", "p", "share explained", "near ties"],
        [
            [
                a.order,
                a.effect_id,
                a.parameter,
                a.value,
                a.stderr if a.stderr is not None else "—",
                a.unit,
                a.delta_bic,
                a.p_value,
                a.share_explained,
                ", ".join(a.near_ties) or "—",
            ]
            for a in result.accepted
        ],
    )
    rounds = "".join(
        f"<h3>Round {r.number} (decimation {r.decimation})</h3>"
        + _table(
            ["effect", "value", "unit", "ΔBIC", "p", "validation", "test share", "simulations", "accepted"],
            [
                [
                    c.effect_id,
                    c.value,
                    c.unit,
                    c.delta_bic,
                    c.p_value,
                    c.validation_improvement,
                    c.test_share,
                    c.simulations,
                    "yes" if c.accepted else "no",
                ]
                for c in r.candidates
            ],
        )
        for r in result.rounds
    )
    where = _table(
        ["kind", "place", "RMS before (N)", "RMS after (N)", "energy share before", "samples"],
        [[p.kind, p.label, p.rms_before_N, p.rms_after_N, p.energy_share_before, p.samples] for p in result.where[:20]],
    )
    bench = _table(
        ["metric", "trial", "measured", "twin before", "twin after", "unit"],
        [[b.metric, b.trial_id, b.measured, b.twin_before, b.twin_after, b.unit] for b in result.benchmark_gaps],
    )
    sig = _table(
        ["trial", "axis", "RMS before", "RMS after", "held-out before", "held-out after"],
        [
            [g.trial_id, g.channel, g.rms_before_N, g.rms_after_N, g.heldout_rms_before_N, g.heldout_rms_after_N]
            for g in result.signal_gaps
        ],
    )
    wsp = "".join(
        f"<h3>{html.escape(w.trial_id)}</h3><p>position residual RMS {1000 * w.rms_before_m:.2f} mm → "
        f"{1000 * w.rms_after_m:.2f} mm; volume measured {1e6 * w.measured_volume_m3:.0f} cm³, twin before "
        f"{1e6 * w.twin_before_volume_m3:.0f} cm³, after {1e6 * w.twin_after_volume_m3:.0f} cm³</p>"
        + _table(
            ["region", "RMS before (m)", "RMS after (m)", "samples"],
            [[r.label, r.rms_before_m, r.rms_after_m, r.samples] for r in w.regions[:10]],
        )
        for w in result.workspace_gaps
    )
    s = result.structure
    fig_html = "".join(
        f'<figure><img src="{html.escape(n)}.png" alt="{html.escape(c)}"><figcaption>{html.escape(c)}</figcaption></figure>'
        for n, c in figs
    )
    page = f"""<!doctype html>
<html lang="en"><head><meta charset="utf-8"><title>Discrepancy — {html.escape(result.session_id)}</title>
<style>body{{font-family:sans-serif;max-width:1100px;margin:2em auto}}table{{border-collapse:collapse;margin:.5em 0}}
td,th{{border:1px solid #ccc;padding:3px 8px}}img{{max-width:100%}}</style></head><body>
<h1>Twin versus measurement</h1>
<p>Session <code>{html.escape(result.session_id)}</code> · twin <code>{html.escape(result.twin_name)}</code> ·
verdict: <b>{html.escape(result.verdict)}</b> · {html.escape(result.gap_summary())}</p>
<h2>Effects added to the twin</h2>{acc if result.accepted else "<p>None.</p>"}
<h2>Residual left</h2><p>A generic state regression removes {100 * s.heldout_share:.1f} % of the held-out residual
(F test p = {s.f_p_value:.2g}; Ljung–Box p = {s.ljung_box_p_value:.2g}) → {
        "structure left that no library effect explains" if s.structured else "no clear structure left"
    }.</p>
{_residual_html(result)}
<h2>Where the twin and the measurement disagree</h2>{where}
{f"<h2>Workspace</h2>{wsp}" if wsp else ""}
<h2>Benchmarks</h2>{bench}
<h2>Signals</h2>{sig}
<h2>Every round</h2>{rounds}
<h2>Figures</h2>{fig_html}
<h2>Not observable in the force residual</h2><ul>{
        "".join(f"<li><code>{html.escape(k)}</code>: {html.escape(v)}</li>" for k, v in result.not_observable.items())
    }</ul>
</body></html>
"""
    atomic_write_text(folder / "report.html", page)
    return {"report": "report.html", **{n: f"{n}.png" for n, _ in figs}}
