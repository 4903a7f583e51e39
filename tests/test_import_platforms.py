"""Force platforms of types 1–4 become the trial's plate_wrench (spec §5.6.1).

Each file carries a known load by construction — an integer force (N) applied at an integer point of
the top surface (mm) with a free moment (N·mm) — recorded as each platform type records it
(haptify_tools.c3d_variants.known_load_channels; every channel exactly a float32). The import's
plate_wrench, summed by §14.1 (haptify.processing.force_plate.total_wrench, the consumer every metric uses), must
give back that load in W to 1e-9 relative, whatever the sensing origin, its sign convention, the
calibration matrix or the plate's pose in the lab.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from haptify.errors import HaptifyError
from haptify.formats.importers import import_c3d, read_c3d
from haptify.formats.storage import open_session
from haptify.formats.validation import validate_session
from haptify.processing.force_plate import PLATE_COLUMNS, center_of_pressure, corner_geometry, total_wrench
from haptify_tools.c3d_variants import (
    PLATFORM_UNITS,
    C3DSpec,
    Platform,
    known_load_channels,
    rectangle_corners,
    unimodular,
    write_c3d,
)
from haptify_tools.example_session import TOUCH_DEVICE

FACTS = {
    "session": {
        "date": "2026-11-25",
        "lab": {"id": "lab-p"},
        "examiner": {"id": "ex-p"},
        "device": TOUCH_DEVICE,
        "device_placement": {"position": [0.0, 0.0, 0.0], "quaternion": [1.0, 0.0, 0.0, 0.0]},
    },
    "trial": {"powered": False, "protocol": "rig.plate_bias"},
}
ORIGINS = {1: (2.0, -3.0, -40.0), 2: (1.0, 2.0, -40.0), 3: (128.0, 256.0, -64.0), 4: (0.0, 0.0, -38.0)}
N = 30  # analog samples: three frames at 10 samples per frame


def load(n: int = N, seed: int = 0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Integer force (N), point of application (mm, on the top surface from its centre) and free moment (N·mm)."""
    rng = np.random.default_rng(seed)
    force = rng.integers(-300, 301, (n, 3)).astype(float)
    force[:, 2] = rng.integers(50, 800, n)  # pressing down: +z of the platform
    return force, rng.integers(-250, 251, (n, 2)).astype(float), rng.integers(-5000, 5001, n).astype(float)


def expected_in_w(force, point, tz, axes: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The load in W (N, N·m about the surface centre): platform frame → W by ``axes`` (columns = the
    platform's axes in W)."""
    moment = np.cross(np.column_stack([point, np.zeros(len(point))]), force)
    moment[:, 2] += tz
    return force @ axes.T, moment / 1000.0 @ axes.T


FLIP = np.diag([1.0, -1.0, -1.0])  # a level platform: x as W's, y and z reversed (z points into the plate)


def plate_file(
    path: Path,
    kind: int,
    channels: np.ndarray,
    corners: np.ndarray,
    origin,
    cal=None,
    points: bool = True,
    platform_type: int | None = None,
) -> Path:
    n_ch = channels.shape[0]
    spec = C3DSpec(
        point_rate=100.0,
        analog_rate=1000.0,
        analog_labels=[f"FP1_{i}" for i in range(n_ch)],
        analog_units=PLATFORM_UNITS.get(kind, ["N"] * n_ch),
        analogs=channels,
        platforms=[Platform(platform_type or kind, corners, np.asarray(origin, float), list(range(1, n_ch + 1)), cal)],
    )
    if points:
        k = np.arange(channels.shape[1] // 10, dtype=float)
        spec.labels, spec.points = ["w"], np.stack([np.column_stack([k, 2 * k, 3 * k])], axis=1)
    else:
        spec.point_rate, spec.frames = 0.0, channels.shape[1] // 10
    return write_c3d(path, spec)


def imported_wrench(session: Path) -> tuple[np.ndarray, np.ndarray, object]:
    s = open_session(session)
    df = s.read(s.trials[0].id, "plate_wrench")
    pos, rot = corner_geometry(s.manifest.rig)
    force, moment = total_wrench(df[PLATE_COLUMNS].to_numpy(), pos, rot)
    return force, moment, s


def assert_relative(got: np.ndarray, want: np.ndarray, rtol: float) -> None:
    assert np.abs(got - want).max() <= rtol * np.abs(want).max(), np.abs(got - want).max()


def run_import(tmp_path: Path, path: Path, name: str = "s", **members):
    m = {"source": "c3d", **json.loads(json.dumps(FACTS)), "platform_wrench": {}, **members}
    return import_c3d(path, tmp_path / name, None, overrides=m)


@pytest.mark.parametrize("kind", [1, 2, 3, 4])
def test_each_platform_type_gives_back_the_known_load_in_w(tmp_path, kind):
    force, point, tz = load(seed=kind)
    cal = unimodular(kind, 6) if kind == 4 else None
    split = (np.arange(N) * 4.0 - 40.0, np.arange(N) % 5 - 2.0) if kind == 3 else None  # the free shares
    channels = known_load_channels(kind, force, point, tz, ORIGINS[kind], cal, split)
    corners = rectangle_corners([300.0, -200.0, 0.0], 600.0, 400.0)
    result = run_import(tmp_path, plate_file(tmp_path / f"t{kind}.c3d", kind, channels, corners, ORIGINS[kind], cal))
    assert result.warnings == []
    assert validate_session(tmp_path / "s").valid
    got_f, got_m, s = imported_wrench(tmp_path / "s")
    want_f, want_m = expected_in_w(force, point, tz, FLIP)
    assert_relative(got_f, want_f, 1e-9)
    assert_relative(got_m, want_m, 1e-9)
    df = s.read(s.trials[0].id, "plate_wrench")
    np.testing.assert_array_equal(df["t"].to_numpy(), np.arange(N) / 1000.0)
    # the load's point, back as the centre of pressure when there is no free moment about x or y
    cop, ok = center_of_pressure(got_f, got_m, min_force_N=1.0)
    assert ok.all()
    np.testing.assert_allclose(cop, np.column_stack([point[:, 0], -point[:, 1]]) / 1000.0, rtol=0, atol=1e-12)


def test_the_calibration_matrix_is_applied_to_a_kistler_platform(tmp_path):
    force, point, tz = load(seed=7)
    cal = unimodular(3, 8)
    outputs = known_load_channels(3, force, point, tz, ORIGINS[3])
    channels = np.rint(np.linalg.inv(cal)) @ outputs  # what the amplifiers recorded
    run_import(tmp_path, plate_file(tmp_path / "k.c3d", 3, channels, rectangle_corners([0, 0, 0], 600.0, 400.0), ORIGINS[3], cal))
    got_f, got_m, _ = imported_wrench(tmp_path / "s")
    want_f, want_m = expected_in_w(force, point, tz, FLIP)
    assert_relative(got_f, want_f, 1e-9)
    assert_relative(got_m, want_m, 1e-9)


@pytest.mark.parametrize(
    "kind,written", [(2, (-1.0, -2.0, 40.0)), (1, (-2.0, 3.0, 40.0)), (3, (128.0, 256.0, 64.0)), (3, (-128.0, -256.0, -64.0))]
)
def test_an_origin_written_with_the_other_sign_is_read_by_the_rule_with_w503(tmp_path, kind, written):
    force, point, tz = load(seed=3)
    channels = known_load_channels(kind, force, point, tz, ORIGINS[kind])  # the standard's origin
    result = run_import(
        tmp_path, plate_file(tmp_path / "o.c3d", kind, channels, rectangle_corners([0, 0, 0], 600.0, 400.0), written)
    )
    [w] = result.warnings
    assert w.code == "W503" and w.pointer == "/FORCE_PLATFORM/ORIGIN"
    assert "W503" in open_session(tmp_path / "s").trials[0].notes
    got_f, got_m, _ = imported_wrench(tmp_path / "s")
    want_f, want_m = expected_in_w(force, point, tz, FLIP)
    assert_relative(got_f, want_f, 1e-9)
    assert_relative(got_m, want_m, 1e-9)


def test_an_analog_only_file_imports_its_platform(tmp_path):
    force, point, tz = load(seed=11)
    channels = known_load_channels(2, force, point, tz, ORIGINS[2])
    path = plate_file(tmp_path / "ao.c3d", 2, channels, rectangle_corners([0, 0, 0], 500.0, 500.0), ORIGINS[2], points=False)
    rec = read_c3d(path)
    assert rec.point_labels == [] and rec.point_rate == 0.0 and rec.warnings == []
    result = run_import(tmp_path, path)
    assert [s["kind"] for s in result.streams] == ["plate_wrench"]
    assert validate_session(tmp_path / "s").valid
    got_f, got_m, s = imported_wrench(tmp_path / "s")
    assert s.manifest.rig.force_plate.size_m == pytest.approx([0.5, 0.5])
    want_f, want_m = expected_in_w(force, point, tz, FLIP)
    assert_relative(got_f, want_f, 1e-9)
    assert_relative(got_m, want_m, 1e-9)


def rotation(q: tuple[float, float, float, float]) -> np.ndarray:
    w, x, y, z = np.asarray(q) / np.linalg.norm(q)
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
            [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
            [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
        ]
    )


quaternions = st.tuples(*[st.floats(-1, 1) for _ in range(4)]).filter(lambda q: math.hypot(*q) > 0.2)


@settings(max_examples=20, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(
    q=quaternions,
    kind=st.sampled_from([1, 2, 3, 4]),
    seed=st.integers(0, 2**16),
    centre=st.tuples(*[st.integers(-2000, 2000) for _ in range(3)]),
)
def test_the_load_in_w_does_not_depend_on_the_plates_pose_in_the_lab(tmp_path_factory, q, kind, seed, centre):
    """W follows the plate (§5.6): a platform placed anywhere, in any orientation, in the lab gives the
    same wrench in W. Its corners are stored as float32 (a 2 m lab coordinate to ~0.1 µm), which turns W
    by up to ~1e-7 rad: hence 1e-6 here, against 1e-9 for the level plates above."""
    tmp = tmp_path_factory.mktemp("rot")
    r = rotation(q)
    force, point, tz = load(n=20, seed=seed)
    cal = unimodular(4, 6) if kind == 4 else None
    channels = known_load_channels(kind, force, point, tz, ORIGINS[kind], cal)
    corners = rectangle_corners(centre, 600.0, 400.0, x_axis=r[:, 0], z_down=r[:, 2])
    run_import(tmp, plate_file(tmp / "r.c3d", kind, channels, corners, ORIGINS[kind], cal))
    got_f, got_m, _ = imported_wrench(tmp / "s")
    want_f, want_m = expected_in_w(force, point, tz, FLIP)
    assert_relative(got_f, want_f, 1e-6)
    assert_relative(got_m, want_m, 1e-6)


@pytest.mark.parametrize(
    "why,kind,change",
    [
        ("type 4 but the file has no FORCE_PLATFORM:CAL_MATRIX", 4, {}),
        ("of type 6", 2, {"platform_type": 6}),
        ("sensor offsets a, b", 3, {"origin": (0.0, 256.0, -64.0)}),
        ("names 6 of the 8 analog channels", 3, {"channels": 6}),
    ],
)
def test_a_platform_whose_channels_give_no_wrench_is_refused_with_e506(tmp_path, why, kind, change):
    force, point, tz = load(seed=5)
    origin = change.get("origin", ORIGINS[kind])
    channels = known_load_channels({4: 2}.get(kind, kind), force, point, tz, ORIGINS[kind])  # type 4's, uncalibrated
    channels = channels[: change.get("channels", len(channels))]
    path = plate_file(
        tmp_path / "bad.c3d",
        kind,
        channels,
        rectangle_corners([0, 0, 0], 600.0, 400.0),
        origin,
        platform_type=change.get("platform_type"),
    )
    with pytest.raises(HaptifyError) as err:
        run_import(tmp_path, path)
    assert err.value.code == "E506" and why in str(err.value)
    assert not (tmp_path / "s").exists()


def test_platform_wrench_needs_the_platform_and_one_source(tmp_path):
    force, point, tz = load(seed=2)
    channels = known_load_channels(2, force, point, tz, ORIGINS[2])
    path = plate_file(tmp_path / "p.c3d", 2, channels, rectangle_corners([0, 0, 0], 600.0, 400.0), ORIGINS[2])
    with pytest.raises(HaptifyError) as err:
        run_import(tmp_path, path, force_plate="none", trial={"powered": False})
    assert err.value.code == "E502" and err.value.findings[0].pointer == "/platform_wrench"
    with pytest.raises(HaptifyError) as err:  # moments in V: not a torque
        run_import(tmp_path, path, platform_wrench={"torque_unit": "V"})
    assert err.value.code == "E504"


@pytest.mark.parametrize("kind", [2, 3, 4])
def test_the_platform_reads_as_ezc3d_computes_it(tmp_path, kind):
    """ezc3d's own force-platform computation (``extract_forceplat_data``: force and centre of pressure
    in the lab frame) on the same file agrees with the imported wrench: same channels, same calibration
    matrix orientation, opposite force (ezc3d reports the ground reaction, §14.1 the load's action)."""
    import ezc3d

    force, point, tz = load(seed=kind + 20)
    cal = unimodular(kind, 6) if kind == 4 else None
    channels = known_load_channels(kind, force, point, tz, ORIGINS[kind], cal)
    path = plate_file(
        tmp_path / "e.c3d", kind, channels, rectangle_corners([300.0, -200.0, 0.0], 600.0, 400.0), ORIGINS[kind], cal
    )
    run_import(tmp_path, path)
    got_f, got_m, _ = imported_wrench(tmp_path / "s")
    theirs = ezc3d.c3d(str(path), extract_forceplat_data=True)["data"]["platform"][0]
    # the level plate: W is the lab frame moved to the plate centre (300, −200, 0) mm; ezc3d gives the
    # platform's reaction on the load (the ground reaction force), the import the load's action on the plate
    np.testing.assert_allclose(got_f, -theirs["force"].T, rtol=1e-9, atol=1e-9)
    cop, _ = center_of_pressure(got_f, got_m, min_force_N=1.0)
    np.testing.assert_allclose(cop * 1000.0 + [300.0, -200.0], theirs["center_of_pressure"][:2].T, rtol=0, atol=1e-6)


REAL = next(
    (
        d / "shared" / "data" / "c3d" / "Qualisys.c3d"
        for d in Path(__file__).resolve().parents[1:4]
        if (d / "shared" / "data" / "c3d" / "Qualisys.c3d").is_file()
    ),
    None,
)


@pytest.mark.skipif(REAL is None, reason="the real Qualisys recording (../shared/data/c3d) is absent")
def test_a_real_amti_platform_is_pressed_down_with_its_cop_on_the_plate(tmp_path):
    """QTM's export of an AMTI platform (type 2, ORIGIN written from the surface to the origin, +34 mm):
    read by the sign rule (W503), the subject's load pushes the plate down (F_z < 0 in W, §14.1; the
    unloaded plate's noise stays within 2 % of the peak) and the centre of pressure lies on the plate
    wherever the load is more than 20 N."""
    result = run_import(tmp_path, REAL, trial={"powered": False})
    assert [w.code for w in result.warnings] == ["W503"]
    force, moment, s = imported_wrench(tmp_path / "s")
    loaded = force[:, 2] < -20.0
    assert loaded.mean() > 0.2 and force[:, 2].max() < 0.02 * -force[:, 2].min()  # up only by unloaded noise
    cop, _ = center_of_pressure(force[loaded], moment[loaded], min_force_N=20.0)
    half = np.array(s.manifest.rig.force_plate.size_m) / 2
    assert (np.abs(cop) <= half).all()
