"""The fixture cases (spec §4.7): every bad-input fixture of ``fixtures/invalid/`` (``CASES``) and every small
valid session of ``fixtures/valid/`` (``VALID``) as a :class:`Case` — its name, the codes validation must
report (fixed by construction, never copied from a validator run), what is broken and how to break it."""

from __future__ import annotations

import os
import shutil
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

from haptify.codes import Code
from haptify.formats.storage import MANIFEST, SessionWriter
from haptify_tools.example_session import TOUCH_DEVICE
from haptify_tools.invalid_fixtures.defects import (
    _csv_edit_line,
    _csv_header,
    _csv_nul_bytes,
    _csv_text_value,
    _device_file,
    _drop_declared_and_file_column,
    _drop_file_column,
    _drop_keys,
    _duplicate_trial_writer,
    _empty,
    _in_turn,
    _int_column,
    _jitter,
    _joint,
    _manifest_latin1,
    _manifest_malformed,
    _markers_nan,
    _oversized,
    _replace_text,
    _retime,
    _scale_quaternions,
    _second_wrench,
    _several,
    _shift_time,
    _swap_times,
    _symlink_stream,
    _sync_trial,
    _truncate,
    _wrong_types,
)
from haptify_tools.invalid_fixtures.session_edits import (
    RENDERING,
    _link_poses,
    _pose,
    add_active_trial,
    add_markers_trial,
    drop_stream,
    edit,
    manifest,
    rewrite_data,
    set_column,
    stream_of,
    trial_of,
)


@dataclass
class Case:
    """One fixture: its name, the expected codes (by construction), what is broken and how to break it."""

    name: str
    codes: list[str]
    description: str
    mutate: Callable[[Path], object] | None = None  # what it returns is not used
    fmt: str = "parquet"
    extend: Callable[[SessionWriter], object] | None = None

    @property
    def exit_code(self) -> int:
        return 1 if any(c.startswith("E") for c in self.codes) else 0


CASES: list[Case] = [
    Case(
        "malformed-json",
        [Code.MANIFEST_MALFORMED_JSON],
        "session.json is cut off in the middle (not well-formed JSON).",
        _manifest_malformed,
    ),
    Case(
        "manifest-not-utf8",
        [Code.MANIFEST_MALFORMED_JSON],
        "session.json is Latin-1, not UTF-8 (an accented examiner id).",
        _manifest_latin1,
    ),
    Case(
        "manifest-nan-literal",
        [Code.MANIFEST_MALFORMED_JSON],
        "session.json uses the non-JSON literal NaN for a rate.",
        lambda f: _replace_text(f, MANIFEST, '"rate_hz": 1000.0', '"rate_hz": NaN'),
    ),
    Case(
        "manifest-missing",
        [Code.MANIFEST_MISSING],
        "The folder holds stream files but no session.json.",
        lambda f: (f / MANIFEST).unlink(),
    ),
    Case(
        "manifest-not-object",
        [Code.SCHEMA_VIOLATION],
        "session.json is a JSON array, not an object.",
        lambda f: (f / MANIFEST).write_text("[]\n", encoding="utf-8"),
    ),
    Case(
        "wrong-types",
        [Code.SCHEMA_VIOLATION],
        "A string where an integer, a boolean and a number are required (repetition, powered, rate_hz).",
        lambda f: edit(f, _wrong_types),
    ),
    Case(
        "missing-required-fields", [Code.SCHEMA_VIOLATION], "session_id and examiner are missing.", lambda f: edit(f, _drop_keys)
    ),
    Case(
        "spec-version-unsupported",
        [Code.SPEC_VERSION_UNSUPPORTED],
        "spec_version is 2.0.",
        lambda f: edit(f, lambda m: m.update(spec_version="2.0")),
    ),
    Case(
        "unknown-protocol",
        [Code.PROTOCOL_UNKNOWN],
        "A trial's protocol is 'juggling'.",
        lambda f: edit(f, lambda m: trial_of(m).update(protocol="juggling")),
    ),
    Case(
        "unknown-stream-kind",
        [Code.SCHEMA_VIOLATION],
        "A stream's kind is 'gyroscope'.",
        lambda f: edit(f, lambda m: stream_of(m, "handle_accel").update(kind="gyroscope")),
    ),
    Case(
        "stream-file-missing",
        [Code.STREAM_FILE_MISSING],
        "The handle_accel file named in session.json was deleted.",
        lambda f: (f / stream_of(manifest(f), "handle_accel")["file"]).unlink(),
    ),
    Case(
        "truncated-parquet",
        [Code.STREAM_UNREADABLE],
        "handle_wrench.parquet is cut to half its length (checksum updated to the cut file).",
        lambda f: _truncate(f, "handle_wrench", 0.5),
    ),
    Case(
        "csv-wrong-header",
        [Code.CSV_HEADER_MALFORMED],
        "CSV session whose handle_wrench header reads time,Fx,... instead of t,fx,...",
        _csv_header,
        fmt="csv",
    ),
    Case(
        "csv-text-value",
        [Code.STREAM_UNREADABLE],
        "CSV session with the text 'nine point eight' in a handle_accel cell.",
        _csv_text_value,
        fmt="csv",
    ),
    Case(
        "csv-plus-sign",
        [Code.STREAM_UNREADABLE],
        "CSV session whose handle_accel az at row 7 is written '+9.81' (spec §3.2 allows no '+' sign).",
        _csv_edit_line("handle_accel", 7, lambda line: ",".join(line.split(",")[:3] + ["+" + line.split(",")[3]])),
        fmt="csv",
    ),
    Case(
        "csv-blank-line",
        [Code.STREAM_UNREADABLE],
        "CSV session whose handle_wrench has a blank line after row 10.",
        _csv_edit_line("handle_wrench", 10, lambda line: line + "\n"),
        fmt="csv",
    ),
    Case("column-not-float", [Code.COLUMN_NOT_NUMERIC], "handle_wrench column fx is stored as 64-bit integers.", _int_column),
    Case(
        "time-not-increasing",
        [Code.TIME_NOT_INCREASING],
        "Two handle_wrench samples are swapped, so t decreases once.",
        lambda f: rewrite_data(f, "handle_wrench", _swap_times),
    ),
    Case(
        "time-nan",
        [Code.TIME_NOT_INCREASING],
        "handle_accel's t is NaN at row 10.",
        lambda f: rewrite_data(f, "handle_accel", set_column("handle_accel", "t", [10], float("nan"))),
    ),
    Case(
        "wrong-units",
        [Code.WRONG_UNIT],
        "handle_wrench declares fx in kN and tx in N*mm.",
        lambda f: edit(
            f,
            lambda m: (
                stream_of(m, "handle_wrench")["columns"][1].update(unit="kN"),
                stream_of(m, "handle_wrench")["columns"][4].update(unit="N*mm"),
            ),
        ),
    ),
    Case(
        "wrong-columns",
        [Code.COLUMN_MISMATCH],
        "handle_wrench lacks the tz column (both in session.json and in the file).",
        _drop_declared_and_file_column,
    ),
    Case(
        "file-columns-differ",
        [Code.COLUMN_MISMATCH],
        "session.json declares tz but the Parquet file has no tz column.",
        _drop_file_column,
    ),
    Case(
        "non-unit-quaternion",
        [Code.QUATERNION_NOT_UNIT],
        "handle_pose quaternions of rows 5-9 are scaled by 1.1 (norm 1.1).",
        lambda f: rewrite_data(f, "handle_pose", _scale_quaternions),
    ),
    Case(
        "nan-in-force",
        [Code.NAN_NOT_ALLOWED],
        "handle_wrench fx is NaN for rows 20-24 (NaN is allowed only in motion capture).",
        lambda f: rewrite_data(f, "handle_wrench", set_column("handle_wrench", "fx", slice(20, 25), float("nan"))),
    ),
    Case(
        "infinity",
        [Code.NON_FINITE_VALUE],
        "handle_accel az is +inf at row 3.",
        lambda f: rewrite_data(f, "handle_accel", set_column("handle_accel", "az", [3], float("inf"))),
    ),
    Case(
        "checksum-mismatch",
        [Code.CHECKSUM_MISMATCH],
        "handle_wrench data changed after its checksum was taken.",
        lambda f: rewrite_data(f, "handle_wrench", set_column("handle_wrench", "fy", slice(0, 200), 0.3), rehash=False),
    ),
    Case(
        "empty-stream",
        [Code.STREAM_EMPTY],
        "handle_wrench holds a header and no rows (rows: 0).",
        lambda f: rewrite_data(f, "handle_wrench", _empty(0)),
    ),
    Case(
        "single-sample-stream",
        [Code.STREAM_EMPTY],
        "handle_wrench holds one sample.",
        lambda f: rewrite_data(f, "handle_wrench", _empty(1)),
    ),
    Case(
        "path-traversal",
        [Code.UNSAFE_PATH],
        "A stream's file is '../../etc/passwd'.",
        lambda f: edit(f, lambda m: stream_of(m, "handle_wrench").update(file="../../etc/passwd")),
    ),
    Case(
        "absolute-path",
        [Code.UNSAFE_PATH],
        "A stream's file is the absolute path '/etc/passwd'.",
        lambda f: edit(f, lambda m: stream_of(m, "handle_wrench").update(file="/etc/passwd")),
    ),
    Case(
        "symlink-absolute",
        [Code.SYMLINK_ESCAPE],
        "handle_wrench.parquet is a symbolic link to /etc/passwd.",
        lambda f: _symlink_stream(f, "handle_wrench", "/etc/passwd"),
    ),
    Case(
        "symlink-relative-escape",
        [Code.SYMLINK_ESCAPE],
        "handle_wrench.parquet is a relative symbolic link into another fixture (a valid file, outside this folder).",
        lambda f: _symlink_stream(
            f, "handle_wrench", "../../../../valid/parquet-basic/trials/free_space-1/handle_wrench.parquet"
        ),
    ),
    Case(
        "symlinked-folder-escape",
        [Code.SYMLINK_ESCAPE],
        "The trials/ folder is a symbolic link to another fixture's trials/ folder.",
        _in_turn(lambda f: shutil.rmtree(f / "trials"), lambda f: os.symlink("../../valid/parquet-basic/trials", f / "trials")),
    ),
    Case(
        "manifest-symlink-escape",
        [Code.SYMLINK_ESCAPE],
        "session.json is a symbolic link to another fixture's session.json.",
        _in_turn(lambda f: (f / MANIFEST).unlink(), lambda f: os.symlink("../../valid/parquet-basic/session.json", f / MANIFEST)),
    ),
    Case(
        "stream-is-folder",
        [Code.STREAM_UNREADABLE],
        "A stream's file names a folder (trials/free_space-1).",
        lambda f: edit(f, lambda m: stream_of(m, "handle_wrench").update(file="trials/free_space-1")),
    ),
    Case(
        "absurd-rows",
        [Code.DECLARED_SIZE_ABSURD],
        "handle_wrench declares 10^12 rows.",
        lambda f: edit(f, lambda m: stream_of(m, "handle_wrench").update(rows=10**12)),
    ),
    Case(
        "absurd-rate",
        [Code.DECLARED_SIZE_ABSURD],
        "handle_accel declares a rate of 10^12 Hz.",
        lambda f: edit(f, lambda m: stream_of(m, "handle_accel").update(rate_hz=1e12)),
    ),
    Case(
        "oversized-file",
        [Code.DECLARED_SIZE_ABSURD],
        "A CSV handle_pose declares 20 rows but its file is padded to ~40 kB; it is not read.",
        _oversized,
        fmt="csv",
    ),
    Case(
        "row-count-mismatch",
        [Code.ROW_COUNT_MISMATCH],
        "handle_wrench declares 150 rows; the file holds 200.",
        lambda f: edit(f, lambda m: stream_of(m, "handle_wrench").update(rows=150)),
    ),
    Case(
        "rate-mismatch",
        [Code.RATE_MISMATCH],
        "handle_wrench is sampled at 950 Hz but declares 1000 Hz (5 % off).",
        lambda f: rewrite_data(f, "handle_wrench", _retime(950.0)),
    ),
    Case(
        "irregular-intervals",
        [Code.SAMPLE_INTERVAL_IRREGULAR],
        "Two handle_wrench samples are moved by 0.6 ms (warning only; the mean rate is exact).",
        lambda f: rewrite_data(f, "handle_wrench", _jitter),
    ),
    Case(
        "rate-below-recommended",
        [Code.RATE_BELOW_RECOMMENDED],
        "handle_accel recorded and declared at 1 kHz; 2 kHz is recommended (warning only).",
        _in_turn(
            lambda f: rewrite_data(f, "handle_accel", lambda df: df.iloc[::2].reset_index(drop=True)),
            lambda f: edit(f, lambda m: stream_of(m, "handle_accel").update(rate_hz=1000.0)),
        ),
    ),
    Case(
        "sensor-range-exceeded",
        [Code.SENSOR_RANGE_EXCEEDED],
        "handle_wrench fz reaches -170 N; the rig declares ±160 N (warning only).",
        lambda f: rewrite_data(f, "handle_wrench", set_column("handle_wrench", "fz", slice(100, 110), -170.0)),
    ),
    Case(
        "non-overlapping-streams",
        [Code.STREAMS_DO_NOT_OVERLAP],
        "handle_pose starts 10 s after the other streams of its trial ended.",
        lambda f: rewrite_data(f, "handle_pose", _shift_time(10.0)),
    ),
    Case(
        "required-stream-missing",
        [Code.REQUIRED_STREAM_MISSING],
        "The free_space trial has no handle_accel stream.",
        lambda f: drop_stream(f, "handle_accel"),
    ),
    Case(
        "recommended-stream-missing",
        [Code.RECOMMENDED_STREAM_MISSING],
        "The free_space trial has no plate_wrench stream (warning only).",
        lambda f: drop_stream(f, "plate_wrench"),
    ),
    Case(
        "rendering-missing",
        [Code.RENDERING_MISSING],
        "An active stiffness trial has no rendering parameters.",
        extend=lambda w: add_active_trial(w, rendering=None),
    ),
    Case(
        "other-without-label",
        [Code.LABEL_MISSING],
        "A trial of protocol 'other' has no label.",
        extend=_in_turn(
            lambda w: w.add_trial("figure8-1", "other", powered=False),
            lambda w: w.add_stream("figure8-1", "handle_pose", _pose(20), rate_hz=100),
        ),
    ),
    Case(
        "powered-flag-unusual",
        [Code.POWERED_FLAG_UNUSUAL],
        "The passive free_space trial is marked powered (warning only).",
        lambda f: edit(f, lambda m: trial_of(m).update(powered=True)),
    ),
    Case(
        "duplicate-trial-id",
        [Code.DUPLICATE_ID],
        "Two trials share the id free_space-1.",
        lambda f: edit(f, lambda m: m["trials"][1].update(id="free_space-1")),
        extend=_duplicate_trial_writer,
    ),
    Case(
        "duplicate-stream-file",
        [Code.DUPLICATE_ID],
        "The second trial's handle_wrench names the first trial's file.",
        lambda f: edit(
            f,
            lambda m: stream_of(m, "handle_wrench", "free_space-2").update(
                file=stream_of(m, "handle_wrench")["file"], sha256=stream_of(m, "handle_wrench")["sha256"]
            ),
        ),
        extend=_duplicate_trial_writer,
    ),
    Case(
        "duplicate-stream-kind",
        [Code.DUPLICATE_STREAM_KIND],
        "One trial holds two handle_wrench streams (two files).",
        _second_wrench,
    ),
    Case(
        "unknown-marker",
        [Code.ENTITY_UNKNOWN],
        "A markers stream names 'h9', which the rig's motion capture does not list.",
        extend=lambda w: add_markers_trial(w, ["h1", "h9"]),
    ),
    Case(
        "markers-partial-nan",
        [Code.NAN_NOT_ALLOWED],
        "Marker h1 has x NaN but y and z present at rows 3-4.",
        _markers_nan(slice(3, 5), ["h1_x"]),
        extend=lambda w: add_markers_trial(w, ["h1", "h2"]),
    ),
    Case(
        "occlusion-high",
        [Code.OCCLUSION_HIGH],
        "Marker h2 is occluded (x, y, z NaN) in 10 of 20 samples (warning only).",
        _markers_nan(slice(5, 15), ["h2_x", "h2_y", "h2_z"]),
        extend=lambda w: add_markers_trial(w, ["h1", "h2"]),
    ),
    Case(
        "wrong-frame",
        [Code.WRONG_FRAME],
        "handle_wrench is declared in frame 'world' instead of 'handle_ft_sensor'.",
        lambda f: edit(f, lambda m: stream_of(m, "handle_wrench").update(frame="world")),
    ),
    Case(
        "manifest-duplicate-key",
        [Code.JSON_DUPLICATE_KEY],
        "session.json names the member 'date' twice at its top level.",
        lambda f: _replace_text(f, MANIFEST, '"date": "2026-11-22",', '"date": "2026-11-22",\n  "date": "2026-11-23",'),
    ),
    Case(
        "device-file-duplicate-key",
        [Code.JSON_DUPLICATE_KEY],
        "device.json names the member 'dof' twice.",
        _in_turn(_device_file({}), lambda f: _replace_text(f, "device.json", '"dof": 6', '"dof": 6,\n  "dof": 3')),
    ),
    Case(
        "csv-nul-bytes",
        [Code.CSV_HEADER_MALFORMED],
        "CSV session whose handle_pose file is NUL bytes with no line end (checksum updated).",
        _csv_nul_bytes,
        fmt="csv",
    ),
    Case("device-file-missing", [Code.DEVICE_FILE_INVALID], "device refers to device.json, which is absent.", _device_file(None)),
    Case(
        "device-file-escape",
        [Code.UNSAFE_PATH],
        "device refers to '../device.json', outside the folder.",
        _device_file(None, "../device.json"),
    ),
    Case(
        "device-file-invalid",
        [Code.DEVICE_FILE_INVALID],
        "device.json gives dof as the string 'six'.",
        _device_file({"dof": "six"}),
    ),
    Case(
        "device-file-quaternion-not-unit",
        [Code.QUATERNION_NOT_UNIT],
        "device.json's DH base quaternion is [0.5, 0, 0, 0] (norm 0.5).",
        _device_file(
            {
                "kinematics": {
                    **TOUCH_DEVICE["kinematics"],
                    "base": {"position": [0.0, 0.0, 0.0], "quaternion": [0.5, 0.0, 0.0, 0.0]},
                }
            }
        ),
    ),
    Case(
        "rig-quaternion-not-unit",
        [Code.QUATERNION_NOT_UNIT],
        "The handle F/T sensor pose in the rig has quaternion [1, 1, 0, 0].",
        lambda f: edit(f, lambda m: m["rig"]["handle"]["ft_sensor"]["pose"].update(quaternion=[1.0, 1.0, 0.0, 0.0])),
    ),
    Case(
        "clock-offset-unknown-file",
        [Code.REFERENCE_UNKNOWN],
        "A clock_offset record names a stream file no stream uses.",
        lambda f: edit(
            f,
            lambda m: m.setdefault("calibration", []).append(
                {"kind": "clock_offset", "id": "sync-1", "stream_file": "trials/free_space-1/mocap.parquet", "offset_s": 0.01}
            ),
        ),
    ),
    Case(
        "calibration-unknown-trial",
        [Code.REFERENCE_UNKNOWN],
        "A plate_bias record names source trial 'plate-bias-9', which does not exist.",
        lambda f: edit(
            f,
            lambda m: m.setdefault("calibration", []).append(
                {"kind": "plate_bias", "id": "bias-1", "source_trial": "plate-bias-9", "bias": [0.0] * 24}
            ),
        ),
    ),
    Case(
        "plate-corner-duplicate-id",
        [Code.DUPLICATE_ID],
        "The force plate's third corner sensor has id 'c1' (c1 twice, c3 missing).",
        lambda f: edit(f, lambda m: m["rig"]["force_plate"]["corners"][2].update(id="c1")),
    ),
    Case(
        "rendering-without-stiffness",
        [Code.SCHEMA_VIOLATION],
        "An active stiffness trial's rendering lacks the required "
        "stiffness_N_per_m (spec §2.5: plane point, normal and stiffness are required).",
        lambda f: edit(f, lambda m: trial_of(m, "stiffness-1")["rendering"].pop("stiffness_N_per_m")),
        extend=add_active_trial,
    ),
    Case(
        "surface-normal-not-unit",
        [Code.SURFACE_NORMAL_NOT_UNIT],
        "An active stiffness trial's rendering surface_normal is [0, 0.1, 1] (norm 1.005).",
        extend=lambda w: add_active_trial(w, rendering={**RENDERING, "surface_normal": [0.0, 0.1, 1.0]}),
    ),
    Case(
        "sync-not-binary",
        [Code.VALUE_NOT_ALLOWED],
        "A sync stream holds the raw trigger voltage (0 V and 5 V), not 0 and 1.",
        extend=_sync_trial(lambda t: 5.0 * ((t >= 0.05) & (t < 0.1))),
    ),
    Case(
        "entities-on-plain-kind",
        [Code.ENTITIES_NOT_ALLOWED],
        "The handle_wrench stream declares entities ['h1'] (only markers and link_poses have them).",
        lambda f: edit(f, lambda m: stream_of(m, "handle_wrench").update(entities=["h1"])),
    ),
    Case(
        "joint-limits-empty",
        [Code.JOINT_LIMITS_EMPTY],
        "The device's q2 range is [0, -0.5] rad: its upper limit lies below its lower one.",
        lambda f: edit(f, lambda m: _joint(m, "q2").update(upper={"constant": -0.5})),
    ),
    Case(
        "joint-limit-later-joint",
        [Code.KINEMATIC_CHAIN_INVALID],
        "The device's q2 upper limit depends on q3, a later joint.",
        lambda f: edit(f, lambda m: _joint(m, "q2").update(upper={"constant": 1.7, "coefficients": {"q3": -0.5}})),
    ),
    Case(
        "date-not-calendar",
        [Code.SCHEMA_VIOLATION],
        "The session's date is 2026-02-30, which matches YYYY-MM-DD but does not exist.",
        lambda f: edit(f, lambda m: m.update(date="2026-02-30")),
    ),
    Case(
        "null-member",
        [Code.NULL_MEMBER],
        "The trial's notes and the rig's name are written as null instead of being omitted (warning only).",
        lambda f: edit(f, lambda m: (trial_of(m).update(notes=None), m["rig"].update(name=None))),
    ),
    Case(
        "several-problems",
        [Code.STREAM_FILE_MISSING, Code.TIME_NOT_INCREASING, Code.NAN_NOT_ALLOWED, Code.RECOMMENDED_STREAM_MISSING],
        "Four independent problems in one trial, all reported: t decreases in handle_wrench, NaN in handle_accel, "
        "the handle_pose file is missing, and plate_wrench is absent.",
        _several,
    ),
]

VALID: list[Case] = [
    Case("parquet-basic", [], "The analytic free-space example session (Parquet)."),
    Case(
        "rendering-minimal",
        [],
        "An active stiffness trial whose rendering has only its required members (plane point, "
        "normal, stiffness): friction, software and loop rate are optional (spec §2.5).",
        extend=lambda w: add_active_trial(
            w, rendering={k: RENDERING[k] for k in ("surface_point_m", "surface_normal", "stiffness_N_per_m")}
        ),
    ),
    Case(
        "csv-multi-trial",
        [],
        "CSV session: a free-space trial, an active stiffness trial with rendering, and a workspace "
        "trial with markers and link poses.",
        fmt="csv",
        extend=_in_turn(
            lambda w: add_active_trial(w, fmt="csv"),
            lambda w: add_markers_trial(w, ["h1", "h2", "h3"], fmt="csv"),
            lambda w: w.add_stream(
                "workspace-1", "link_poses", _link_poses(["handle"]), rate_hz=100, fmt="csv", entities=["handle"]
            ),
        ),
    ),
]
