"""The registry's read-side statistics and rankings on values known by construction (issue 9)."""

from __future__ import annotations

import math
from statistics import fmean, stdev

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from haptify.results import DeviceSummary, Implementation, MetricResult, ResultsFile
from haptify_tools.registry.aggregate import Entry, aggregate_devices, comparison, device_slug, leaderboard, slugify


def results(model: str, metrics: dict[str, list[float] | float], manufacturer: str = "3D Systems") -> ResultsFile:
    """A results file whose scalar metrics have the given repetitions (a bare float: no repetitions)."""
    out = []
    for mid, reps in metrics.items():
        if isinstance(reps, list):
            out.append(MetricResult(id=mid, value=fmean(reps), unit="u", per_repetition=reps, n=len(reps),
                                    sd=stdev(reps) if len(reps) > 1 else None, definition_version="1.0.0"))
        else:
            out.append(MetricResult(id=mid, value=reps, unit="u", n=1, definition_version="1.0.0"))
    return ResultsFile(implementation=Implementation(name="haptify", version="1"), session_id=f"s-{model}",
                       device=DeviceSummary(manufacturer=manufacturer, model=model), manifest_sha256="a" * 64, metrics=out)


def entry(i: int, lab: str, r: ResultsFile) -> Entry:
    return Entry(submission_id=f"{i:020x}", lab=lab, results=r)


def test_device_statistics_known_by_construction():
    # lab A: two sessions with repetitions [1, 3] and [5]; lab B: one session [10, 14]
    entries = [entry(1, "lab-a", results("Touch", {"vibration.rms": [1.0, 3.0]})),
               entry(2, "lab-a", results("Touch", {"vibration.rms": [5.0]})),
               entry(3, "lab-b", results("Touch", {"vibration.rms": [10.0, 14.0]}))]
    devices = aggregate_devices(entries)
    assert list(devices) == ["3d-systems-touch"]
    m = devices["3d-systems-touch"].metrics["vibration.rms"]
    assert m.lab_means == {"lab-a": 3.5, "lab-b": 12.0}  # lab A: mean of 2 and 5
    assert m.mean == pytest.approx(7.75)  # each lab weighs the same
    assert m.sd == pytest.approx(stdev([1, 3, 5, 10, 14]))
    assert m.sd_labs == pytest.approx(stdev([3.5, 12.0]))
    assert m.sd_repetitions == pytest.approx(math.sqrt((1 * 2.0 + 1 * 8.0) / 2))  # variances 2 and 8, 1 dof each
    assert (m.min, m.max, m.n_labs, m.n_submissions, m.n_repetitions) == (1.0, 14.0, 2, 3, 5)


def test_single_values_and_vectors():
    r = results("Touch", {"workspace.modeled_volume": 0.02})
    r.metrics.append(MetricResult(id="dynamics.force_rmse", value=[0.1, 0.2, 0.3], unit="N", n=1, definition_version="1.0.0"))
    m = aggregate_devices([entry(1, "lab-a", r)])["3d-systems-touch"]
    assert set(m.metrics) == {"workspace.modeled_volume"}  # per-axis metrics are not aggregated
    single = m.metrics["workspace.modeled_volume"]
    assert (single.mean, single.sd, single.sd_labs, single.sd_repetitions, single.n_repetitions) == (0.02, None, None, None, 1)


def test_slugs_group_devices_and_ignore_serials():
    a = results("Touch X", {"vibration.rms": [0.04]})
    b = results("Touch X", {"vibration.rms": [0.05]})
    b.device.serial = "SN-2"
    devices = aggregate_devices([entry(1, "lab-a", a), entry(2, "lab-b", b)])
    assert list(devices) == ["3d-systems-touch-x"] and device_slug(a.device) == "3d-systems-touch-x"
    assert slugify("  Force Dimension / omega.6 ") == "force-dimension-omega-6"


def test_leaderboard_directions_and_ties():
    entries = [entry(1, "lab", results("A", {"vibration.rms": [0.05], "workspace.measured_volume": [0.010],
                                             "stiffness.accuracy": [90.0], "free_space.speed_mean": [0.2]})),
               entry(2, "lab", results("B", {"vibration.rms": [0.03], "workspace.measured_volume": [0.012],
                                             "stiffness.accuracy": [104.0], "free_space.speed_mean": [0.1]})),
               entry(3, "lab", results("C", {"vibration.rms": [0.05], "workspace.measured_volume": [0.011],
                                             "stiffness.accuracy": [97.0]}))]
    devices = aggregate_devices(entries)

    def order(metric):
        rows, rule = leaderboard(metric, devices)
        return [(r.rank, r.device.model) for r in rows], rule

    rows, rule = order("vibration.rms")  # lower is better; A and C tie
    assert rows == [(1, "B"), (2, "A"), (2, "C")] and rule.startswith("Lower is better")
    assert order("workspace.measured_volume")[0] == [(1, "B"), (2, "C"), (3, "A")]
    assert order("stiffness.accuracy")[0] == [(1, "C"), (2, "B"), (3, "A")]  # closest to 100 %
    rows, rule = order("free_space.speed_mean")  # no direction: ascending, unranked, only devices that have it
    assert rows == [(None, "B"), (None, "A")] and rule.startswith("Not ranked")


def test_comparison_is_table_iii_for_n_devices():
    devices = aggregate_devices([entry(1, "lab", results("Touch", {"vibration.rms": [0.06, 0.08]})),
                                 entry(2, "lab", results("Touch X", {"vibration.rms": [0.04, 0.04]})),
                                 entry(3, "lab", results("Falcon", {"workspace.measured_volume": [0.001]}, manufacturer="Novint"))])
    table = comparison([devices["3d-systems-touch-x"], devices["3d-systems-touch"], devices["novint-falcon"]])
    assert table.header == ["Metric", "3D Systems Touch X", "3D Systems Touch", "Novint Falcon"]
    rms = next(r for r in table.rows if r[0].startswith("Free-space vibration RMS"))
    assert rms[1:] == ["0.04 ± 0", "0.07 ± 0.014", "—"]
    volume = next(r for r in table.rows if r[0].startswith("Workspace volume"))
    assert volume[1:] == ["—", "—", "1000"]  # 0.001 m^3 shown in cm^3


@settings(max_examples=60, deadline=None)
@given(st.lists(st.tuples(st.sampled_from(["lab-a", "lab-b", "lab-c"]),
                          st.lists(st.floats(-1e3, 1e3, allow_nan=False), min_size=1, max_size=4)),
                min_size=1, max_size=6), st.randoms())
def test_aggregate_is_order_free_and_bounded(samples, rnd):
    entries = [entry(i, lab, results("Touch", {"vibration.rms": reps})) for i, (lab, reps) in enumerate(samples)]
    m = aggregate_devices(entries)["3d-systems-touch"].metrics["vibration.rms"]
    shuffled = entries[:]
    rnd.shuffle(shuffled)
    m2 = aggregate_devices(shuffled)["3d-systems-touch"].metrics["vibration.rms"]
    assert m2.mean == pytest.approx(m.mean, abs=1e-9) and m2.n_repetitions == m.n_repetitions
    assert m.min - 1e-9 <= m.mean <= m.max + 1e-9
    assert m.n_labs == len({lab for lab, _ in samples})
