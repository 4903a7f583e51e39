"""Leaderboard ordering of the registry on device results known by construction (spec §17.5)."""

from __future__ import annotations

from hypothesis import given, settings
from hypothesis import strategies as st

from haptify_tools.registry.leaderboard import leaderboard, rankings, rule_text


def device(model: str, **means: float | list[float]) -> dict:
    """A ``Registry.device_results`` answer with the given metric means (ids with '_' for '.')."""
    return {
        "device": {"slug": model.lower(), "manufacturer": "Maker", "model": model},
        "metrics": [{"metric": k.replace("__", "."), "mean": v, "unit": "u"} for k, v in means.items()],
    }


DEVICES = [
    device("A", vibration__rms=0.05, workspace__measured_volume=0.010, stiffness__accuracy=90.0, free_space__speed_mean=0.2),
    device("B", vibration__rms=0.03, workspace__measured_volume=0.012, stiffness__accuracy=104.0, free_space__speed_mean=0.1),
    device(
        "C", vibration__rms=0.05, workspace__measured_volume=0.011, stiffness__accuracy=97.0, dynamics__force_rmse=[0.1, 0.2, 0.3]
    ),
]


def order(metric: str) -> list[tuple[int | None, str]]:
    return [(r.rank, r.device["model"]) for r in leaderboard(metric, DEVICES)]


def test_lower_is_better_with_shared_ranks():
    assert order("vibration.rms") == [(1, "B"), (2, "A"), (2, "C")]
    assert rule_text("vibration.rms").startswith("Lower is better")


def test_higher_and_target():
    assert order("workspace.measured_volume") == [(1, "B"), (2, "C"), (3, "A")]
    assert order("stiffness.accuracy") == [(1, "C"), (2, "B"), (3, "A")]  # |97-100| < |104-100| < |90-100|
    assert rule_text("stiffness.accuracy").startswith("Closest to 100 is better")


def test_unranked_metric_ascending_and_only_devices_that_have_it():
    assert order("free_space.speed_mean") == [(None, "B"), (None, "A")]
    assert rule_text("free_space.speed_mean").startswith("Not ranked")


def test_vector_metrics_have_no_leaderboard():
    assert order("dynamics.force_rmse") == []


def test_rankings_name_known_metrics_and_directions():
    from haptify_tools.registry.api_read import metric_definitions

    defs = metric_definitions()
    for metric_id, rule in rankings().items():
        assert metric_id in defs, metric_id
        assert defs[metric_id].shape == "scalar", metric_id
        assert rule["better"] in ("lower", "higher") or set(rule["better"]) == {"target"}
        assert "§" in rule["why"]  # each direction cites the paper


@settings(max_examples=80, deadline=None)
@given(st.lists(st.floats(-1e6, 1e6, allow_nan=False), min_size=1, max_size=8), st.randoms())
def test_ranks_follow_the_means_whatever_the_input_order(means, rnd):
    devices = [device(f"D{i}", vibration__rms=m) for i, m in enumerate(means)]
    rnd.shuffle(devices)
    rows = leaderboard("vibration.rms", devices)
    got = [r.metric["mean"] for r in rows]
    assert got == sorted(means)  # lower is better
    for a, b in zip(rows, rows[1:]):
        assert (a.rank == b.rank) == (a.metric["mean"] == b.metric["mean"])
        assert a.rank <= b.rank
    assert rows[0].rank == 1 and all(r.rank == 1 + sum(x < r.metric["mean"] for x in means) for r in rows)


def test_a_vector_metric_with_one_repetition_compares_without_an_sd():
    """The compare page built a results file whose vector sd held None (one repetition): HTTP 500."""
    from types import SimpleNamespace

    from haptify.pipeline.compare import build_table
    from haptify.pipeline.results import DeviceSummary, Implementation, MetricResult, ResultsFile
    from haptify_tools.registry.aggregates import aggregate, defined_sd

    row = SimpleNamespace(per_repetition_json="[]", value_json="[0.1, 0.2, 0.3]", unit="N", definition_version="1.0.0")
    agg = aggregate("dynamics.error_vs_distance", [({"lab": "lab-a"}, row)])
    assert agg["mean"] == [0.1, 0.2, 0.3] and agg["sd"] == [None, None, None]
    metric = MetricResult(
        id=agg["metric"],
        value=agg["mean"],
        unit=agg["unit"],
        n=agg["repetitions"],
        sd=defined_sd(agg["sd"]),
        definition_version=agg["definition_version"],
    )
    assert metric.sd is None and defined_sd([0.5, 0.25]) == [0.5, 0.25] and defined_sd(0.5) == 0.5
    results = ResultsFile(
        implementation=Implementation(name="r", version="0"),
        session_id="s",
        device=DeviceSummary(manufacturer="Acme", model="A"),
        manifest_sha256="0" * 64,
        metrics=[metric],
    )
    assert build_table([results]).header == ["Metric", "Acme A"]
