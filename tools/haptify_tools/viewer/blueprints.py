"""A rerun blueprint per protocol: what a person wants to see first for each kind of trial (spec §2.5 protocols).

Each trial gets a tab. The tab holds the 3-D view of the world (plate, device base, that trial's
entities of every role) beside a column of time-series views chosen for the protocol (for example
force against time beside the 3-D view for stiffness, the point cloud large for workspace). Time
series that exist but are not in the protocol's list sit in a tab group under the chosen ones, so
nothing recorded is hidden. A last tab holds the session summary and the results table.
"""

from __future__ import annotations

from dataclasses import dataclass

import rerun.blueprint as rrb

from haptify_tools.viewer.plan import ROLES, SERIES, TIMELINE, Plan, TrialPlan

# Time-series views: name → (title, series keys overlaid in that view).
VIEWS: dict[str, tuple[str, list[str | tuple[str, ...]]]] = {
    # the calibrated hand force, or the raw force in W when the session cannot be calibrated
    "hand_force": ("hand force in W", [("hand_force/calibrated", "hand_force/raw_world")]),
    "hand_torque": ("hand torque in W (calibrated)", ["hand_torque/calibrated"]),
    "ft_force": ("F/T force (raw, sensor frame)", ["handle/force_raw"]),
    "ft_torque": ("F/T torque (raw, sensor frame)", ["handle/torque_raw"]),
    "accel": ("acceleration (raw sensor; calibrated W)", ["accel/raw", "accel/world"]),
    "vibration": ("vibration: DFT321 of the high-passed acceleration", ["accel/dft321"]),
    "normal_force": ("normal force: commanded vs felt", ["contact/normal_force"]),
    "plate_force": ("plate force (W)", ["plate/force"]),
    "plate_cop": ("plate centre of pressure", ["plate/cop"]),
    "plate_corners": ("plate corner forces (raw)", ["plate/corner_force_raw"]),
    "plate_corner_torques": ("plate corner torques (raw)", ["plate/corner_torque_raw"]),
    "commanded_vs_felt": ("commanded vs felt force (W)", ["commanded/force", ("hand_force/calibrated", "hand_force/raw_world")]),
    "commanded_torque": ("commanded torque (W)", ["commanded/torque"]),
    "penetration": ("penetration of the virtual surface", ["penetration", "contact/penetration"]),
    "position": ("handle position (W)", ["handle/position"]),
}


@dataclass(frozen=True)
class Layout:
    """How a protocol's tab opens: 3-D first (left) or series first, their shares, the series views."""

    views: tuple[str, ...]
    spatial_first: bool = True
    shares: tuple[float, float] = (1.0, 1.0)


PASSIVE_MOTION = Layout(("hand_force", "hand_torque", "accel", "vibration", "plate_force"))
PLATE_RIG = Layout(("plate_force", "plate_cop", "plate_corners"))
LAYOUTS: dict[str, Layout] = {
    "workspace": Layout(("position",), shares=(3.0, 1.0)),
    "free_space": PASSIVE_MOTION,
    "local_dynamic": PASSIVE_MOTION,
    "frictionless_surface": Layout(("commanded_vs_felt", "normal_force", "penetration", "accel")),
    "stiffness": Layout(("normal_force", "penetration", "commanded_vs_felt"), spatial_first=False),
    "rig.handle_calibration": Layout(("ft_force", "ft_torque", "accel", "hand_force")),
    "rig.plate_bias": PLATE_RIG,
    "rig.plate_impact": PLATE_RIG,
    "rig.plate_cop": PLATE_RIG,
    "rig.baseline_vibration": Layout(("accel", "vibration", "position")),
    "other": Layout(tuple(VIEWS)),
}


def series_view(plan: Plan, tp: TrialPlan, title: str, keys: list[str | tuple[str, ...]]) -> rrb.TimeSeriesView | None:
    """A time-series view overlaying ``keys`` of every role; None when the first key (the view's subject,
    e.g. the commanded force of "commanded vs felt") was not recorded for any role.

    A tuple of keys stands for alternatives: per role, the first one that was recorded.
    """
    paths = plan.paths()
    contents = []
    for i, key in enumerate(keys):
        for role in ROLES:
            present = [k for k in ((key,) if isinstance(key, str) else key) if f"/series/{tp.key}/{role}/{k}" in paths]
            if present:
                contents.append(f"+ $origin/{role}/{present[0]}")
        if i == 0 and not contents:
            return None
    return rrb.TimeSeriesView(origin=f"/series/{tp.key}", contents=contents, name=title)


def spatial_view(tp: TrialPlan) -> rrb.Spatial3DView:
    """The world (W, z up) with the rig and this trial's entities of every role (spec §1.2)."""
    return rrb.Spatial3DView(
        origin="/world",
        name=f"{tp.trial.id} · 3-D",
        contents=["+ /world", "+ /world/plate/**", "+ /world/device/**", f"+ /world/{tp.key}/**"],
    )


def trial_tab(plan: Plan, tp: TrialPlan) -> rrb.Container:
    """The tab of one trial, laid out for its protocol (spec §2.5)."""
    layout = LAYOUTS[tp.trial.protocol]
    chosen = [v for v in (series_view(plan, tp, *VIEWS[name]) for name in layout.views) if v is not None]
    shown = {k for name in layout.views for key in VIEWS[name][1] for k in ((key,) if isinstance(key, str) else key)}
    rest = [v for v in (series_view(plan, tp, SERIES[k][0], [k]) for k in SERIES if k not in shown) if v is not None]
    column = chosen + ([rrb.Tabs(*rest, name="more series")] if rest else [])
    spatial = spatial_view(tp)
    name = f"{tp.trial.id} ({tp.trial.protocol})"
    if not column:
        return rrb.Horizontal(spatial, name=name)
    series = rrb.Vertical(*column, name="time series")
    parts = (spatial, series) if layout.spatial_first else (series, spatial)
    shares = layout.shares if layout.spatial_first else layout.shares[::-1]
    return rrb.Horizontal(*parts, column_shares=list(shares), name=name)


def blueprint_for(plan: Plan) -> rrb.Blueprint:
    """One tab per trial (protocol layout) plus a session tab; the time panel on the session timeline."""
    docs = [rrb.TextDocumentView(origin="/session", name="session")]
    if plan.has_results:
        docs.append(rrb.TextDocumentView(origin="/results", name="results"))
    tabs = [trial_tab(plan, tp) for tp in plan.trials] + [rrb.Horizontal(*docs, name="session & results")]
    return rrb.Blueprint(rrb.Tabs(*tabs), rrb.TimePanel(timeline=TIMELINE), collapse_panels=False)
