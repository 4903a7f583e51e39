"""Validation rules of spec chapters 2–4 added in the validator polish: plate corner ids (E107), the
rendering normal (E307), the sync trigger (E214), entities on plain kinds (E215), the device's joint
limits and chain order (E115, E116), calendar dates (E104) and the CSV grammar (E112). Answers are known
by construction."""

from __future__ import annotations

import itertools
import math
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from haptify.errors import HaptifyError
from haptify.formats.session_format import ALLOWED_VALUES, Kinematics
from haptify.formats.storage import CSV_CHUNK_BYTES, check_csv_grammar, csv_grammar
from haptify.formats.validation import (
    NORMAL_NORM_TOLERANCE,
    kinematics_findings,
    validate_session,
)
from haptify.processing.kinematics import RANGE_LATTICE_POINTS as LIMIT_LATTICE_POINTS
from haptify.processing.kinematics import configurations_from_unit
from haptify_tools.example_session import TOUCH_DEVICE, example_writer
from haptify_tools.invalid_fixtures import defects, session_edits


def _write(tmp_path: Path, extend=None, name: str = "s") -> Path:
    w = example_writer(duration_s=0.2)
    if extend is not None:
        extend(w)
    return w.write(tmp_path / name)


# --- force-plate corner ids (spec §2.2, §2.4: E107) ------------------------------------------------


@pytest.mark.parametrize("k, to", [(1, "c1"), (3, "c2"), (0, "c4")])
def test_a_repeated_corner_id_is_e107_at_the_repeat_naming_the_missing_id(tmp_path: Path, k: int, to: str):
    folder = _write(tmp_path)
    session_edits.edit(folder, lambda m: m["rig"]["force_plate"]["corners"][k].update(id=to))
    report = validate_session(folder)
    (f,) = report.findings
    ids = ["c1", "c2", "c3", "c4"]
    ids[k] = to
    first_repeat = next(i for i, c in enumerate(ids) if c in ids[:i])
    missing = ({"c1", "c2", "c3", "c4"} - set(ids)).pop()
    assert (f.code, f.pointer, f.found) == ("E107", f"/rig/force_plate/corners/{first_repeat}/id", ids)
    assert missing in f.message


def test_corner_ids_in_any_order_are_valid(tmp_path: Path):
    folder = _write(tmp_path)
    session_edits.edit(folder, lambda m: m["rig"]["force_plate"].update(corners=m["rig"]["force_plate"]["corners"][::-1]))
    assert validate_session(folder).findings == []


# --- rendering surface normal (spec §2.5: E307) ------------------------------------------------------


def _with_normal(tmp_path: Path, normal: list[float]) -> Path:
    return _write(
        tmp_path, lambda w: session_edits.add_active_trial(w, rendering={**session_edits.RENDERING, "surface_normal": normal})
    )


@pytest.mark.parametrize(
    "excess, flagged",
    [
        (0.9 * NORMAL_NORM_TOLERANCE, False),
        (-0.9 * NORMAL_NORM_TOLERANCE, False),
        (1.5 * NORMAL_NORM_TOLERANCE, True),
        (-1.5 * NORMAL_NORM_TOLERANCE, True),
    ],
)
def test_surface_normal_tolerance_is_that_of_quaternions(tmp_path: Path, excess: float, flagged: bool):
    assert NORMAL_NORM_TOLERANCE == 1e-3
    direction = np.array([0.0, 0.6, 0.8])  # a unit vector, exactly
    normal = [float(v) for v in direction * (1.0 + excess)]
    report = validate_session(_with_normal(tmp_path, normal))
    assert ("E307" in report.codes) is flagged
    if flagged:
        (f,) = report.findings
        assert (f.pointer, f.found) == ("/trials/1/rendering/surface_normal", normal)
        assert f"{1 + excess:.6g}" in f.message


@pytest.mark.parametrize("normal", [[0.0, 0.7071, 0.7071], [0.5774, 0.5774, 0.5774], [0.0, 0.0, -1.0]])
def test_normals_written_with_four_decimals_are_unit(tmp_path: Path, normal):
    assert validate_session(_with_normal(tmp_path, normal)).findings == []


@pytest.mark.parametrize("normal", [[0.0, 0.0, 0.0], [0.0, 0.1, 1.0], [1e308, 1e308, 0.0]])
def test_zero_tilted_unnormalised_and_huge_normals_are_e307_never_e999(tmp_path: Path, normal):
    assert validate_session(_with_normal(tmp_path, normal)).codes == ["E307"]


# --- the sync trigger (spec §2.6: E214) ----------------------------------------------------------------


def _with_sync(tmp_path: Path, trigger: np.ndarray, name: str = "s") -> Path:
    def extend(w):
        t = np.arange(trigger.size) / 1000.0
        w.add_stream(session_edits.TRIAL, "sync", {"t": t, "trigger": trigger}, rate_hz=1000)

    return _write(tmp_path, extend, name)


def test_the_allowed_trigger_values_are_the_kind_tables_open_and_closed():
    assert ALLOWED_VALUES == {("sync", "trigger"): (0.0, 1.0)}


def test_a_binary_trigger_is_valid_and_a_half_level_is_e214_with_count_and_span(tmp_path: Path):
    trigger = np.zeros(200)
    trigger[50:100] = 1.0
    assert validate_session(_with_sync(tmp_path, trigger, "ok")).findings == []
    trigger[60:63] = 0.5
    trigger[150] = 2.0
    (f,) = validate_session(_with_sync(tmp_path, trigger, "bad")).findings
    assert (f.code, f.column, f.found, f.expected) == ("E214", "trigger", [0.5, 2.0], [0.0, 1.0])
    assert "holds 4 values" in f.message
    assert f.time_range == pytest.approx((0.060, 0.150))


def test_nan_in_the_trigger_is_e204_not_e214(tmp_path: Path):
    trigger = np.zeros(200)
    trigger[10] = np.nan
    assert validate_session(_with_sync(tmp_path, trigger)).codes == ["E204"]


@settings(max_examples=15, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(
    bits=st.lists(st.sampled_from([0.0, 1.0]), min_size=200, max_size=200),
    odd=st.dictionaries(
        st.integers(0, 199), st.floats(-10, 10, allow_nan=False).filter(lambda v: v not in (0.0, 1.0)), max_size=5
    ),
)
def test_e214_counts_exactly_the_values_outside_zero_and_one(tmp_path_factory, bits, odd):
    trigger = np.array(bits)
    for i, v in odd.items():
        trigger[i] = v
    report = validate_session(_with_sync(tmp_path_factory.mktemp("sync"), trigger))
    if not odd:
        assert report.findings == []
    else:
        (f,) = report.findings
        assert f.code == "E214" and f"holds {len(odd)} values" in f.message
        assert f.time_range == pytest.approx((min(odd) / 1000.0, max(odd) / 1000.0))


# --- entities only on markers and link_poses (spec §2.6: E215) --------------------------------------


@pytest.mark.parametrize("kind, entities", [("handle_wrench", ["h1"]), ("handle_pose", []), ("plate_wrench", ["c1", "c2"])])
def test_entities_on_a_kind_without_entities_are_e215(tmp_path: Path, kind: str, entities):
    folder = _write(tmp_path)
    session_edits.edit(folder, lambda m: session_edits.stream_of(m, kind).update(entities=entities))
    (f,) = validate_session(folder).findings
    index = [s["kind"] for s in session_edits.trial_of(session_edits.manifest(folder))["streams"]].index(kind)
    assert (f.code, f.pointer, f.found) == ("E215", f"/trials/0/streams/{index}/entities", entities)


def test_entities_on_markers_and_link_poses_stay_valid(tmp_path: Path):
    folder = _write(
        tmp_path,
        lambda w: (
            session_edits.add_markers_trial(w, ["h1", "h2"]),
            w.add_stream("workspace-1", "link_poses", session_edits._link_poses(["handle"]), rate_hz=100, entities=["handle"]),
        ),
    )
    assert validate_session(folder).findings == []


# --- the device's kinematic chain (spec §2.3: E115, E116) ----------------------------------------------


def _kin(limits: list[tuple[dict, dict]], names: list[str] | None = None) -> Kinematics:
    names = names or [f"q{i + 1}" for i in range(len(limits))]
    return Kinematics.model_validate(
        {
            "base": {"position": [0, 0, 0], "quaternion": [1, 0, 0, 0]},
            "joints": [
                {"name": n, "a": 0.1, "alpha": 0.0, "d": 0.0, "lower": lo, "upper": hi} for n, (lo, hi) in zip(names, limits)
            ],
        }
    )


def _codes(kin: Kinematics) -> list[tuple[str, str]]:
    return [(f.code, f.pointer) for f in kinematics_findings(kin, "device.json", "/kinematics")]


def test_the_touch_chain_is_valid():
    assert _codes(Kinematics.model_validate(TOUCH_DEVICE["kinematics"])) == []


@pytest.mark.parametrize("lower, upper, flagged", [(0.0, -0.5, True), (0.0, -1e-12, True), (0.3, 0.3, False), (-1.0, 1.0, False)])
def test_a_constant_range_is_empty_exactly_when_upper_is_below_lower(lower: float, upper: float, flagged: bool):
    kin = _kin(
        [
            ({"constant": -1.0}, {"constant": 1.0}),
            ({"constant": lower}, {"constant": upper}),
            ({"constant": -1.0}, {"constant": 1.0}),
        ]
    )
    assert _codes(kin) == ([("E115", "/kinematics/joints/1")] if flagged else [])


def test_a_coupled_range_empty_everywhere_is_e115_and_empty_somewhere_is_allowed():
    q2 = ({"constant": 0.0}, {"constant": 1.7628})
    # q3 ≤ -2.5 - 0.85 q2 < -2.4435 = lower for every q2 in [0, 1.7628]: empty everywhere
    everywhere = _kin(
        [({"constant": -1.0}, {"constant": 1.0}), q2, ({"constant": -2.4435}, {"constant": -2.5, "coefficients": {"q2": -0.85}})]
    )
    assert _codes(everywhere) == [("E115", "/kinematics/joints/2")]
    # q3 ≤ -2.0 - 0.85 q2: non-empty for q2 < 0.52 only — the rest of q2's range is unreachable, not an error
    somewhere = _kin(
        [({"constant": -1.0}, {"constant": 1.0}), q2, ({"constant": -2.4435}, {"constant": -2.0, "coefficients": {"q2": -0.85}})]
    )
    assert _codes(somewhere) == []


@pytest.mark.parametrize("names, bad", [(["q2", "q1", "q3"], [0, 1]), (["q1", "q2", "q4"], [2]), (["q1", "q1", "q3"], [1])])
def test_joints_are_named_q1_to_qn_in_chain_order(names: list[str], bad: list[int]):
    kin = _kin([({"constant": -1.0}, {"constant": 1.0})] * 3, names)
    assert _codes(kin) == [("E116", f"/kinematics/joints/{i}/name") for i in bad]


@pytest.mark.parametrize("joint, side, other", [(1, "upper", "q3"), (1, "lower", "q2"), (0, "upper", "q2")])
def test_a_limit_may_name_earlier_joints_only(joint: int, side: str, other: str):
    limits = [({"constant": -1.0}, {"constant": 1.0}) for _ in range(3)]
    lo, hi = limits[joint]
    limits[joint] = (
        (lo, {"constant": 1.0, "coefficients": {other: 0.1}})
        if side == "upper"
        else ({"constant": -1.0, "coefficients": {other: 0.1}}, hi)
    )
    assert _codes(_kin(limits)) == [("E116", f"/kinematics/joints/{joint}/{side}/coefficients/{other}")]


@st.composite
def chains(draw):
    """3-joint chains with random constant and coupled limits (couplings on earlier joints only)."""
    limits = []
    for i in range(3):
        pair = []
        for _ in range(2):
            coeffs = {f"q{k + 1}": draw(st.floats(-1.5, 1.5, allow_nan=False)) for k in range(i) if draw(st.booleans())}
            pair.append({"constant": draw(st.floats(-2, 2, allow_nan=False)), "coefficients": coeffs})
        limits.append(tuple(pair))
    return _kin(limits)


@settings(max_examples=200, deadline=None)
@given(kin=chains())
def test_e115_is_exactly_compute_s_no_configuration_condition(kin: Kinematics):
    """Oracle: the modeled workspace's own lattice (spec §8.3 step 1, haptify.processing.kinematics) has no feasible row."""
    n = len(kin.joints)
    axis = np.linspace(0.0, 1.0, LIMIT_LATTICE_POINTS)
    unit = np.array(list(itertools.product(axis, repeat=n)))
    feasible = ~np.isnan(configurations_from_unit(kin, unit)).any(axis=1)
    assert ("E115" in [c for c, _ in _codes(kin)]) is (not feasible.any())


def test_empty_limits_in_a_device_file_are_reported_in_that_file(tmp_path: Path):
    joints = [dict(j) for j in TOUCH_DEVICE["kinematics"]["joints"]]
    joints[0] = {**joints[0], "lower": {"constant": 1.0}, "upper": {"constant": -1.0}}
    folder = _write(tmp_path)
    defects._device_file({"kinematics": {**TOUCH_DEVICE["kinematics"], "joints": joints}})(folder)
    (f,) = validate_session(folder).findings
    assert (f.code, f.file, f.pointer) == ("E115", "device.json", "/kinematics/joints/0")
    assert f.found == {"lower": {"constant": 1.0, "coefficients": {}}, "upper": {"constant": -1.0, "coefficients": {}}}
    assert math.isclose(float(f.message.split("by at least ")[1].split(" rad")[0]), 2.0)


# --- the date (spec §2.1: E104) --------------------------------------------------------------------------


@pytest.mark.parametrize(
    "date, valid", [("2026-02-29", False), ("2028-02-29", True), ("2026-04-31", False), ("2026-12-31", True)]
)
def test_the_date_is_a_calendar_date(tmp_path: Path, date: str, valid: bool):
    folder = _write(tmp_path)
    session_edits.edit(folder, lambda m: m.update(date=date))
    findings = validate_session(folder).findings
    assert [(f.code, f.pointer) for f in findings] == ([] if valid else [("E104", "/date")])


# --- the CSV grammar (spec §3.2: E112) --------------------------------------------------------------


def _grammar(tmp_path: Path, text: str, columns=("t", "x")):
    path = tmp_path / "s.csv"
    path.write_bytes(text.encode("utf-8"))
    try:
        check_csv_grammar(path, list(columns), "s.csv")
    except HaptifyError as err:
        (f,) = err.findings
        return f
    return None


@pytest.mark.parametrize("chunk", [3, 64, CSV_CHUNK_BYTES])
@pytest.mark.parametrize(
    "text", ["t,x\n0,1\n1,NaN\n", "t,x\n0,1\n1,2", "t,x\r\n0,1\r\n1,-2.5e-3\r\n", "t,x\n0,1.\n1,1E+5\n", "t,x\n-0,-1.e-300\n"]
)
def test_csv_lines_of_the_grammar_pass(tmp_path: Path, monkeypatch, text: str, chunk: int):
    monkeypatch.setattr(csv_grammar, "CSV_CHUNK_BYTES", chunk)
    assert _grammar(tmp_path, text) is None


@pytest.mark.parametrize("chunk", [3, CSV_CHUNK_BYTES])
@pytest.mark.parametrize(
    "text, line, column, found",
    [
        ("t,x\n0,1\n1,nan\n", 3, "x", "nan"),
        ("t,x\n0,1\n1,inf\n", 3, "x", "inf"),
        ("t,x\n+0,1\n", 2, "t", "+0"),
        ('t,x\n0,"1"\n', 2, "x", '"1"'),
        ("t,x\n0, 1\n", 2, "x", " 1"),
        ("t,x\n0,\n", 2, "x", ""),
        ("t,x\n0,.5\n", 2, "x", ".5"),
        ("t,x\n0,1.2.3\n", 2, "x", "1.2.3"),
        ("t,x\n0,1\n\n1,2\n", 3, None, "a blank line"),
        ("t,x\n0,1\n1,2\n\n", 4, None, "a blank line"),
        ("t,x\n0,1,2\n", 2, None, 3),
        ("t,x\n0,1\r1,2\n", 2, None, 3),
        ("t,x\r\n0,1\r\n1,2\r\r\n", 3, "x", "2\r"),
    ],
)
def test_csv_lines_outside_the_grammar_are_e112_naming_line_and_column(
    tmp_path: Path, monkeypatch, text, line, column, found, chunk
):
    monkeypatch.setattr(csv_grammar, "CSV_CHUNK_BYTES", chunk)
    f = _grammar(tmp_path, text)
    assert (f.code, f.column, f.found) == ("E112", column, found)
    assert f"line {line} " in f.message


def test_a_lone_carriage_return_line_end_is_e112(tmp_path: Path):
    assert _grammar(tmp_path, "t,x\r0,1\r1,2\r").code == "E112"


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(
    values=st.lists(st.lists(st.floats(allow_infinity=False), min_size=3, max_size=3), min_size=1, max_size=30),
    crlf=st.booleans(),
    last_eol=st.booleans(),
    chunk=st.sampled_from([5, 17, CSV_CHUNK_BYTES]),
)
def test_every_shortest_round_trip_float_and_nan_passes(tmp_path: Path, monkeypatch, values, crlf, last_eol, chunk):
    """What spec §3.2 tells writers to print (Python's repr, NaN as 'NaN') always satisfies the grammar."""
    monkeypatch.setattr(csv_grammar, "CSV_CHUNK_BYTES", chunk)
    eol = "\r\n" if crlf else "\n"
    rows = [",".join("NaN" if math.isnan(v) else repr(v) for v in row) for row in values]
    text = "a,b,c" + eol + eol.join(rows) + (eol if last_eol else "")
    assert _grammar(tmp_path, text, ("a", "b", "c")) is None


# --- null members (spec §2.1: W407) ------------------------------------------------------------------


def test_every_tolerated_null_is_w407_at_its_pointer_and_the_session_stays_valid(tmp_path: Path):
    folder = _write(tmp_path)
    session_edits.edit(
        folder,
        lambda m: (
            session_edits.trial_of(m).update(notes=None, label=None),
            m["rig"].update(name=None),
            session_edits.stream_of(m, "handle_wrench").update(entities=None),
        ),
    )
    report = validate_session(folder)
    assert sorted((f.code, f.pointer) for f in report.findings) == [
        ("W407", "/rig/name"),
        ("W407", "/trials/0/label"),
        ("W407", "/trials/0/notes"),
        ("W407", "/trials/0/streams/0/entities"),
    ]
    assert {i.trial for i in report.items if i.finding.pointer.startswith("/trials")} == {"free_space-1"}
    assert report.exit_code == 0


def test_a_null_the_schema_refuses_is_e104_alone(tmp_path: Path):
    folder = _write(tmp_path)
    session_edits.edit(folder, lambda m: m.update(calibration=None))
    assert [(f.code, f.pointer) for f in validate_session(folder).findings] == [("E104", "/calibration")]


def test_nulls_in_the_device_file_are_w407_in_that_file(tmp_path: Path):
    folder = _write(tmp_path)
    defects._device_file({"serial": None})(folder)
    assert [(f.code, f.file, f.pointer) for f in validate_session(folder).findings] == [("W407", "device.json", "/serial")]
