"""The discrepancy workflow end to end (design §5; discrepancy README §1–4): where → name → add → show.

:func:`run_discrepancy` reads the measured session, re-simulates every force trial with the twin
along the measured path, names missing effects by forward selection (:mod:`.identify`), writes the
updated twin and shows the gap before and after: ``discrepancy.json`` (:class:`.model.DiscrepancyFile`),
``report.html`` with its figures, and ``twin.json``. The output folder is built beside the target and
renamed into place (spec §3.6 style), so an interrupted run leaves nothing half-written.
"""

from __future__ import annotations

import shutil
import tempfile
from contextlib import ExitStack
from dataclasses import replace
from pathlib import Path
from typing import Callable

import numpy as np

from haptify.errors import HaptifyError
from haptify.formats.storage import atomic_write_json, replace_folder_atomically
from haptify.metrics.free_space import magnitude_stats
from haptify.metrics.stiffness import FitRule, fit_stiffness
from haptify.metrics.surface import planar_stats
from haptify.pipeline.gate import require_valid_session
from haptify_tools.discrepancy import data as dt
from haptify_tools.discrepancy import drive_rest
from haptify_tools.discrepancy import hand_path as hp
from haptify_tools.discrepancy import stats as st
from haptify_tools.discrepancy import workspace as ws
from haptify_tools.discrepancy.floor import (
    FLOOR_REPLAYS,
    GAP_ALPHA,
    Floor,
    Parameter,
    gap_above_floor,
    heldout_gap,
    replay_durations,
    replay_floors,
)
from haptify_tools.discrepancy.identify import Selection, accepted_parameters, pool_size, process_pool, select_effects
from haptify_tools.discrepancy.library import NOT_OBSERVABLE
from haptify_tools.discrepancy.model import (
    AcceptedEffect,
    BenchmarkGap,
    BenchmarkNotComputed,
    CandidateFit,
    Channel,
    DiscrepancyFile,
    ForceSource,
    Place,
    PlaceKind,
    ResidualCell,
    ResidualShape,
    RoundResult,
    SignalGap,
    StateShape,
    Structure,
    Verdict,
    WorkspaceGap,
    WorkspaceRegion,
)
from haptify_tools.twin.model import TwinFile, twin_from_dict, twin_to_dict, write_twin

SPEED_BANDS_M_PER_S = (0.0, 0.02, 0.05, 0.1, 0.2, np.inf)
MIN_PLACE_SHARE = 0.01  # regions holding fewer rows than this share are not ranked
CHANNELS: tuple[Channel, ...] = ("fx", "fy", "fz")


def _finite(x: float) -> float | None:
    return float(x) if np.isfinite(x) else None


def localise(trials: list[dt.MeasuredTrial], before: dict, after: dict) -> list[Place]:
    """Rank the places of disagreement (benchmark, trial, contact/free space, speed band, workspace
    region = tertiles of the path along each world axis) by residual RMS before (spec-free; discrepancy README §1)."""
    rows = []
    for tr in trials:
        v = tr.valid
        rb, ra = (tr.force - before[tr.trial_id])[v], (tr.force - after[tr.trial_id])[v]
        rows.append((tr, v, rb, ra))
    if not rows:
        return []
    total = sum(float(np.sum(rb**2)) for _, _, rb, _ in rows) or 1.0
    n_all = sum(len(rb) for _, _, rb, _ in rows)
    pos_all = np.concatenate([tr.position[v] for tr, v, _, _ in rows])
    cuts = [np.quantile(pos_all[:, k], [1 / 3, 2 / 3]) for k in range(3)]
    groups: dict[tuple[PlaceKind, str], list[tuple[np.ndarray, np.ndarray]]] = {}

    def add(kind: PlaceKind, label: str, rb: np.ndarray, ra: np.ndarray) -> None:
        groups.setdefault((kind, label), []).append((rb, ra))

    for tr, v, rb, ra in rows:
        add("benchmark", tr.protocol, rb, ra)
        add("trial", tr.trial_id, rb, ra)
        c = tr.contact[v]
        if tr.active:
            add("contact", "in contact with the rendered surface", rb[c], ra[c])
            add("contact", "powered, not in contact", rb[~c], ra[~c])
        else:
            add("contact", "free space (unpowered)", rb, ra)
        sp = tr.speed[v]
        for lo, hi in zip(SPEED_BANDS_M_PER_S[:-1], SPEED_BANDS_M_PER_S[1:]):
            m = (sp >= lo) & (sp < hi)
            add("speed_band", f"{lo:g}–{hi:g} m/s", rb[m], ra[m])
        p = tr.position[v]
        cell = np.stack([np.searchsorted(cuts[k], p[:, k]) for k in range(3)], axis=1)
        names = ("low", "mid", "high")
        for key in {tuple(r) for r in cell.tolist()}:
            m = np.all(cell == key, axis=1)
            add("region", "x " + names[key[0]] + ", y " + names[key[1]] + ", z " + names[key[2]], rb[m], ra[m])
    places = []
    for (kind, label), parts in groups.items():
        rb = np.concatenate([a for a, _ in parts])
        ra = np.concatenate([b for _, b in parts])
        if len(rb) == 0 or (kind in ("region", "speed_band") and len(rb) < MIN_PLACE_SHARE * n_all):
            continue
        places.append(
            Place(
                kind=kind,
                label=label,
                rms_before_N=float(np.sqrt(np.mean(np.sum(rb**2, axis=1)))),
                rms_after_N=float(np.sqrt(np.mean(np.sum(ra**2, axis=1)))),
                energy_share_before=float(np.sum(rb**2) / total),
                samples=int(len(rb)),
            )
        )
    places.sort(key=lambda p: (-p.rms_before_N, p.kind, p.label))
    return places


def signal_gaps(design: st.Design, trials: list[dt.MeasuredTrial], before: dict, after: dict) -> list[SignalGap]:
    """Per trial and axis: force residual RMS (N) over every usable row and over the held-out blocks, before and after (discrepancy README §4)."""
    out = []
    for tr in trials:
        v = tr.valid
        held = st.heldout_rows(tr)
        for k, ch in enumerate(CHANNELS):
            rb, ra = tr.force[:, k] - before[tr.trial_id][:, k], tr.force[:, k] - after[tr.trial_id][:, k]
            rms = lambda x, m: float(np.sqrt(np.mean(x[m] ** 2))) if m.any() else 0.0  # noqa: E731
            out.append(
                SignalGap(
                    trial_id=tr.trial_id,
                    protocol=tr.protocol,
                    channel=ch,
                    rms_before_N=rms(rb, v),
                    rms_after_N=rms(ra, v),
                    heldout_rms_before_N=rms(rb, held),
                    heldout_rms_after_N=rms(ra, held),
                )
            )
    return out


#: the benchmarks :func:`benchmark_values` computes per protocol (listed when its operator fails)
BENCHMARKS_OF = {
    "free_space": ("free_space.force_mean",),
    "local_dynamic": ("force_mean",),
    "other": ("force_mean",),
    "frictionless_surface": ("surface.planar_force_mean",),
    "stiffness": ("stiffness.measured", "stiffness.peak_force"),
}


def benchmark_values(tr: dt.MeasuredTrial, force: np.ndarray, errors: list | None = None) -> dict[str, tuple[float, str]]:
    """The reference's benchmark operators applied to ``force`` on the trial's grid: free-space mean force
    (spec §9.2), planar force on the surface (§12.3), rendered stiffness and peak force (§13.3).

    The stiffness fit keeps the contact transient (§13.2's first samples of a press): the presses are the
    measured trial's contact runs, which begin where the measured device's encoders cross the plane, and a
    twin with a stiffer drive is already well up its rise there — setting its first samples aside would leave
    it too few (a twin without drive compliance would have no stiffness at all). An operator's coded error
    (:class:`~haptify.errors.HaptifyError`) is appended to ``errors`` as ``(metrics, code, message)``."""
    v = tr.valid
    out: dict[str, tuple[float, str]] = {}
    try:
        if tr.protocol in ("free_space", "local_dynamic", "other"):
            out["free_space.force_mean" if tr.protocol == "free_space" else "force_mean"] = (
                magnitude_stats(force[v])["mean"],
                "N",
            )
        if tr.active:
            pen, n = tr.penetration()
            c = v & tr.contact
            if tr.protocol == "frictionless_surface" and c.sum() >= 2:
                out["surface.planar_force_mean"] = (planar_stats(force[c], n)["mean"], "N")
            if tr.protocol == "stiffness":
                rule = replace(FitRule.at_rate(tr.rate_hz), settle=0)
                fit = fit_stiffness(tr.t[v], pen[v], force[v] @ n, tr.contact[v], tr.trial_id, rule=rule)
                out["stiffness.measured"] = (fit.stiffness, "N/m")
                out["stiffness.peak_force"] = (float(np.max((force @ n)[c])) if c.any() else 0.0, "N")
    except HaptifyError as e:
        if errors is not None:
            errors.append((list(BENCHMARKS_OF.get(tr.protocol, ())), e.code, str(e)))
    return out


def benchmark_gaps(
    trials: list[dt.MeasuredTrial], before: dict, after: dict
) -> tuple[list[BenchmarkGap], list[BenchmarkNotComputed]]:
    """Benchmarks from the measured force and from the twin's force before and after, per trial, in each metric's unit,
    and those an operator could not compute, with its code (discrepancy README §4)."""
    out: list[BenchmarkGap] = []
    missing: list[BenchmarkNotComputed] = []
    for tr in trials:
        values = {}
        forces: tuple[tuple[ForceSource, np.ndarray], ...] = (
            ("measured", tr.force),
            ("twin before", before[tr.trial_id]),
            ("twin after", after[tr.trial_id]),
        )
        for source, force in forces:
            errors: list = []
            values[source] = benchmark_values(tr, force, errors)
            missing += [
                BenchmarkNotComputed(metrics=m, trial_id=tr.trial_id, force=source, code=c, message=msg) for m, c, msg in errors
            ]
        m, b, a = values["measured"], values["twin before"], values["twin after"]
        for key in m:
            if key in b and key in a:
                out.append(
                    BenchmarkGap(
                        metric=key,
                        trial_id=tr.trial_id,
                        unit=m[key][1],
                        measured=m[key][0],
                        twin_before=b[key][0],
                        twin_after=a[key][0],
                    )
                )
    return out, missing


def _tertile_labels(points: np.ndarray) -> list[str]:
    cuts = [np.quantile(points[:, k], [1 / 3, 2 / 3]) for k in range(3)]
    names = ("low", "mid", "high")
    cell = np.stack([np.searchsorted(cuts[k], points[:, k]) for k in range(3)], axis=1)
    return [f"x {names[a]}, y {names[b]}, z {names[c]}" for a, b, c in cell.tolist()]


def workspace_gaps(sel: Selection) -> list[WorkspaceGap]:
    """Per workspace trial: residual RMS and volumes (reference operator) measured / twin before / after,
    and the regions where the sweep and the twin disagree (the Touch's missing lower lobe, paper §VI-A)."""
    from haptify.metrics.workspace import volume_solid

    out: list[WorkspaceGap] = []
    if sel.sweeps is None or sel.initial_sweep is None or sel.final_sweep is None:
        return out
    for sw in sel.sweeps.items:
        ok = sw.valid
        before, after = sel.initial_sweep[sw.trial_id], sel.final_sweep[sw.trial_id]
        rb = np.linalg.norm(sw.position - before, axis=1)[ok]
        ra = np.linalg.norm(sw.position - after, axis=1)[ok]
        labels = np.asarray(_tertile_labels(sw.position[ok]))
        regions = []
        for lab in sorted(set(labels.tolist())):
            m = labels == lab
            if m.sum() >= MIN_PLACE_SHARE * len(labels):
                regions.append(
                    WorkspaceRegion(
                        label=lab,
                        rms_before_m=float(np.sqrt(np.mean(rb[m] ** 2))),
                        rms_after_m=float(np.sqrt(np.mean(ra[m] ** 2))),
                        samples=int(m.sum()),
                    )
                )
        regions.sort(key=lambda r: -r.rms_before_m)
        vol = lambda p: float(volume_solid(p[np.all(np.isfinite(p), axis=1)]).volume)  # noqa: E731
        out.append(
            WorkspaceGap(
                trial_id=sw.trial_id,
                rms_before_m=float(np.sqrt(np.mean(rb**2))),
                rms_after_m=float(np.sqrt(np.mean(ra**2))),
                measured_volume_m3=vol(sw.position),
                twin_before_volume_m3=vol(before),
                twin_after_volume_m3=vol(after),
                regions=regions,
            )
        )
    return out


def annotate_twin(twin: TwinFile, result: DiscrepancyFile) -> TwinFile:
    """The updated twin with each identified parameter's uncertainty and evidence (± s.e., 95 % interval, ΔBIC, p) in
    the effect's ``sources`` (discrepancy README §4)."""
    data = twin_to_dict(twin)
    for a in result.accepted:
        holder = data["rig"] if a.effect_id == "handle.connector_mass" else data["effects"]
        if a.effect_id == ws.EFFECT_ID:
            box = next(p for p in holder[a.effect_id]["primitives"] if p["shape"] == "box")
            key = f"primitives.{box['name']}.top"
        else:
            key = a.parameter
        se = lambda e: f"{e:.3g}" if e is not None else "n/a"  # noqa: E731
        if a.per_drive is not None:
            shown = "per drive " + ", ".join(f"{v:.6g} ± {se(e)}" for v, e in zip(a.per_drive, a.per_drive_stderr or []))
        else:
            shown = f"{a.value:.6g} ± {se(a.stderr)}" + (f" (95 % {a.ci95[0]:.6g} … {a.ci95[1]:.6g})" if a.ci95 else "")
        holder[a.effect_id].setdefault("sources", {})[key] = (
            f"identified by haptify discrepancy: {shown} {a.unit} (1 s.e.), ΔBIC {a.delta_bic:.1f}, p {a.p_value:.2g}"
        )
    return twin_from_dict(data)


def _per_drive(f) -> dict:
    """The interval and per-drive fields of a fit's record (discrepancy README §2, per drive; §3, uncertainty)."""
    ci = None if f.values is not None or f.interval is None or not np.all(np.isfinite(f.interval)) else list(f.interval)
    return {
        "ci95": ci,
        "per_drive": f.values,
        "per_drive_stderr": [_finite(e) for e in f.stderrs] if f.stderrs else None,
        "per_drive_delta_bic": f.per_drive_score.delta_bic if f.per_drive_score is not None else None,
    }


def build_result(session_id: str, twin: TwinFile, trials: list[dt.MeasuredTrial], sel: Selection) -> DiscrepancyFile:
    """Assemble :class:`DiscrepancyFile` from a finished selection, its floor not yet known (:func:`with_floor`) (discrepancy README §4)."""
    rounds = []
    for i, r in enumerate(sel.rounds):
        cands = [
            CandidateFit(
                effect_id=f.candidate.effect_id,
                parameter=f.candidate.parameter,
                value=f.value,
                stderr=_finite(f.stderr),
                unit=f.candidate.unit,
                delta_bic=f.score.delta_bic,
                p_value=f.score.p_value,
                validation_improvement=f.score.validation_improvement,
                test_share=f.score.test_share,
                simulations=f.simulations,
                accepted=bool(r.accepted and f is r.chosen),
                **_per_drive(f),
            )
            for f in r.fits
        ]
        rounds.append(RoundResult(number=i + 1, decimation=r.design.decimation, candidates=cands, near_ties=r.near_ties))
    accepted = [
        AcceptedEffect(
            order=i + 1,
            effect_id=f.candidate.effect_id,
            parameter=f.candidate.parameter,
            value=f.value,
            stderr=_finite(f.stderr),
            unit=f.candidate.unit,
            delta_bic=f.score.delta_bic,
            p_value=f.score.p_value,
            share_explained=f.score.test_share,
            near_ties=sel.rounds[i].near_ties,
            **_per_drive(f),
        )
        for i, f in enumerate(sel.accepted)
    ]
    s = sel.structure
    design = sel.rounds[0].design
    wgaps = workspace_gaps(sel)
    before, after = heldout_gap(trials, sel.initial_sim), heldout_gap(trials, sel.final_sim)
    bench, missing = benchmark_gaps(trials, sel.initial_sim, sel.final_sim)
    bench += [
        BenchmarkGap(
            metric="workspace.measured_volume",
            trial_id=w.trial_id,
            unit="m^3",
            measured=w.measured_volume_m3,
            twin_before=w.twin_before_volume_m3,
            twin_after=w.twin_after_volume_m3,
        )
        for w in wgaps
    ]
    return DiscrepancyFile(
        session_id=session_id,
        twin_name=twin.name,
        verdict=verdict_of(bool(accepted), s["structured"], False),
        accepted=accepted,
        rounds=rounds,
        residual=residual_shape(sel.shape),
        benchmarks_not_computed=missing,
        structure=Structure(**s),
        where=localise(trials, sel.initial_sim, sel.final_sim),
        signal_gaps=signal_gaps(design, trials, sel.initial_sim, sel.final_sim),
        benchmark_gaps=bench,
        workspace_gaps=wgaps,
        heldout_gap_before_N=before,
        heldout_gap_after_N=after,
        not_observable=dict(NOT_OBSERVABLE),
        hand_path={tr.trial_id: tr.path_source for tr in trials},
        settings={
            "path_crossover_hz": hp.PATH_CROSSOVER_HZ,
            "pose_cutoff_hz": hp.POSE_CUTOFF_HZ,
            "free_space_pose_cutoff_hz": hp.POSE_CUTOFF_BY_PROTOCOL_HZ["free_space"],
            "orientation_cutoff_hz": hp.ORIENTATION_CUTOFF_HZ,
            "clip_margin_s": hp.CLIP_MARGIN_S,
            "gap_margin_s": hp.GAP_MARGIN_S,
            "rest_window_s": drive_rest.REST_WINDOW_S,
            "rest_range_rad": drive_rest.REST_RANGE_RAD,
            "residual_cutoff_hz": dt.RESIDUAL_CUTOFF_HZ,
            "sim_rate_hz": dt.SIM_RATE_HZ,
            "bic_min": st.BIC_MIN,
            "p_max": st.P_MAX,
            "validation_min": st.VALIDATION_MIN,
            "structure_share": st.STRUCTURE_SHARE,
        },
    )


def verdict_of(accepted: bool, structured: bool, gap_significant: bool) -> Verdict:
    """The verdict (discrepancy README §3): never "no discrepancy" (nor "explained") while the generic regression finds
    structure left or the held-out gap is significantly above the floor — then "unexplained residual", whatever was
    accepted. The residual's shape describes what is left; it does not decide the verdict."""
    if structured or gap_significant:
        return "unexplained residual"
    return "explained" if accepted else "no discrepancy"


def residual_shape(shape: dict | None) -> ResidualShape | None:
    """The model of :func:`.shape.characterise`'s result (discrepancy README §3)."""
    if shape is None:
        return None
    best = shape["best"]
    offset = shape["offset_share"] >= st.STRUCTURE_SHARE
    text = best.description if best is not None else "no rows to judge"
    if offset:
        text = f"a constant offset per trial ({100 * shape['offset_share']:.0f} % of the held-out energy); beyond it, {text}"
    return ResidualShape(
        where=[ResidualCell(protocol=p, channel=c, heldout_rms_N=r, share=e) for p, c, r, e in shape["where"]],
        offset_share=shape["offset_share"],
        states=[
            StateShape(
                state=f.state,
                kind=f.kind,
                heldout_r2=f.heldout_r2,
                description=f.description,
                period=f.period,
                amplitude_N=f.amplitude_N,
                amplitude_per_axis_N=f.amplitude_per_axis_N,
            )
            for f in shape["fits"]
        ],
        follows=best.state if best is not None else None,
        description=text,
        structured=shape["structured"],
    )


def replay_parameters(sel: Selection) -> tuple[Parameter, ...]:
    """The accepted force effects' identified values, one per drive when identified per drive, for the replays to
    estimate again (discrepancy README §3, uncertainty; :func:`.identify.accepted_parameters`)."""
    return accepted_parameters(sel.accepted)


def _replay_uncertainty(accepted: list[AcceptedEffect], floor: Floor) -> list[AcceptedEffect]:
    """``accepted`` with the replays' standard errors and 95 % intervals (:meth:`.floor.Floor.uncertainty`)."""
    out = []
    for a in accepted:
        idx = [j for j, q in enumerate(floor.params) if q.candidate.effect_id == a.effect_id]
        if not idx or not floor.estimates:
            out.append(a)
            continue
        unc = [floor.uncertainty(j) for j in idx]
        if a.per_drive is not None:
            out.append(a.model_copy(update={"per_drive_stderr": [_finite(se) for se, _ in unc]}))
        else:
            se, (lo, hi) = unc[0]
            out.append(a.model_copy(update={"stderr": _finite(se), "ci95": [lo, hi] if np.isfinite(se) else None}))
    return out


def with_floor(result: DiscrepancyFile, floor: Floor | None) -> DiscrepancyFile:
    """``result`` with its floor (:func:`.floor.replay_floors`; None: no trial could be replayed), the held-out gaps above it,
    the gap test and the verdict it decides (discrepancy README §3, §4)."""
    if floor is None:
        return result
    bound = floor.bound_N
    p = floor.p_value(result.heldout_gap_after_N)
    significant = p < GAP_ALPHA
    return result.model_copy(
        update={
            "accepted": _replay_uncertainty(result.accepted, floor),
            "floor_N": bound,
            "floor_replays_N": list(floor.replays_N),
            "floor_median_N": floor.median_N,
            "gap_p_value": p,
            "gap_significant": significant,
            "verdict": verdict_of(bool(result.accepted), result.structure.structured, significant),
            "heldout_gap_above_floor_before_N": gap_above_floor(result.heldout_gap_before_N, bound),
            "heldout_gap_above_floor_after_N": gap_above_floor(result.heldout_gap_after_N, bound),
        }
    )


def assess(
    twin: TwinFile,
    trials: list[dt.MeasuredTrial],
    durations: dict[str, float],
    session_id: str = "",
    max_effects: int = 5,
    workers: int = 1,
    log: Callable[[str], object] | None = None,
    sweeps: list | None = None,
) -> tuple[DiscrepancyFile, Selection]:
    """What :func:`run_discrepancy` decides, for force trials already loaded, without outputs: selection, result, floor
    (from replays of ``durations``, :func:`.floor.replay_durations`) and verdict (discrepancy README §2–4)."""
    sel = select_effects(twin, trials, max_effects=max_effects, log=log, workers=workers, sweeps=sweeps)
    result = build_result(session_id, twin, trials, sel)
    return with_floor(result, replay_floors(sel.twin, durations, params=replay_parameters(sel)) if trials else None), sel


def run_discrepancy(
    session_path: str | Path,
    twin: TwinFile,
    out: str | Path | None = None,
    *,
    max_effects: int = 5,
    overwrite: bool = False,
    log: Callable[[str], object] | None = None,
    report: bool = True,
    workers: int = 1,
    overlay: bool = True,
    client=None,
) -> tuple[DiscrepancyFile, Selection]:
    """Run the workflow (discrepancy README §1–4); with ``out`` write ``discrepancy.json``, ``twin.json`` and ``report.html`` there.

    ``overlay``: also write ``overlay.rrd`` for the viewer (when ``report``). ``workers``: processes that run the
    simulations trial by trial (0: one per CPU, at most 4; results do not depend on it, :func:`.identify.select_effects`);
    with more than one, the floor's replay runs in its own process while the figures and the overlay are drawn. With a Dask
    ``client`` the simulations and the floor's replay run on its cluster instead (spec §17.9). Returns the result and the selection
    (its simulations, for callers that draw or test).
    """
    session, _ = require_valid_session(session_path)
    sweeps = ws.load_sweeps(session)
    trials = dt.load_measured(session, required=not sweeps)
    sel = select_effects(twin, trials, max_effects=max_effects, log=log, workers=workers, sweeps=sweeps, client=client)
    durations = replay_durations(session, trials)
    target = Path(out) if out is not None else None
    build = None
    if target is not None:
        target.parent.mkdir(parents=True, exist_ok=True)
        build = Path(tempfile.mkdtemp(prefix=f".{target.name}.tmp-", dir=target.parent))
        build.chmod(0o755)  # an ordinary folder once renamed into place
    try:
        with ExitStack() as stack:
            pending = None
            if trials and client is not None:
                pending = client.submit(replay_floors, sel.twin, durations, FLOOR_REPLAYS, replay_parameters(sel), pure=False)
            elif trials and pool_size(workers) > 1:
                pool = stack.enter_context(process_pool(1))
                pending = pool.submit(replay_floors, sel.twin, durations, FLOOR_REPLAYS, replay_parameters(sel))
            figures = plan = None
            if build is not None and report:
                from haptify_tools.discrepancy.report import write_figures

                figures = write_figures(build, trials, sel)
                if overlay:
                    from haptify_tools.discrepancy.overlay import overlay_plan

                    plan = overlay_plan(session, trials, sel.final_sim)
            result = build_result(session.session_id, twin, trials, sel)
            if pending is not None:
                floor = pending.result()
            else:
                floor = replay_floors(sel.twin, durations, params=replay_parameters(sel)) if trials else None
        result = with_floor(result, floor)
        if build is not None and target is not None:  # (one is made with the other)
            files = {"twin": "twin.json"}
            write_twin(annotate_twin(sel.twin, result), build / "twin.json")
            if figures is not None:
                from haptify_tools.discrepancy.report import write_report

                files.update(write_report(build, result, figures))
            if plan is not None:
                from haptify_tools.discrepancy.overlay import write_overlay

                write_overlay(plan, result, build / "overlay.rrd")
                files["overlay"] = "overlay.rrd"
            result.files = files
            atomic_write_json(build / "discrepancy.json", result.model_dump(mode="json"))
            replace_folder_atomically(build, target, overwrite)
    except BaseException:
        if build is not None:
            shutil.rmtree(build, ignore_errors=True)  # nothing half-written is left beside the target
        raise
    return result, sel
