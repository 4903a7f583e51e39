"""The device twin file (TWIN.md): presets, effect ids, switching effects off, setting parameters, errors."""

from __future__ import annotations

import json

import pytest

from haptify.errors import HaptifyError
from haptify.formats.session_format import Device
from haptify_tools.example_session import TOUCH_DEVICE
from haptify_tools.twin.model import (
    EFFECT_IDS,
    PRESETS,
    TwinFile,
    disable,
    load_twin,
    preset,
    set_param,
    twin_from_dict,
    twin_to_dict,
    write_twin,
)

ISSUE_EFFECT_IDS = (
    "gravity",
    "inertia",
    "friction.coulomb",
    "friction.viscous",
    "friction.stribeck",
    "drive.series_elasticity",
    "drive.torque_saturation",
    "drive.force_cutoff",
    "drive.backlash",
    "kinematics.base_collision",
    "kinematics.link_length",
    "sensor.bias",
    "handle.connector_mass",
    "vibration.device",
)


def codes(err: HaptifyError) -> list[str]:
    return [f.code for f in err.findings]


def test_effect_ids_are_exactly_the_issues():
    assert EFFECT_IDS == ISSUE_EFFECT_IDS


@pytest.mark.parametrize("name", PRESETS)
def test_presets_load_and_name_every_effect(name):
    tw = preset(name)
    data = twin_to_dict(tw)
    keys = set(data["effects"]) | set(data["rig"])
    assert set(EFFECT_IDS) <= keys
    for eid in EFFECT_IDS:
        assert isinstance(tw.effect(eid).enabled, bool)
    # the nominal description is a valid standard device description
    Device.model_validate(data["device"])


@pytest.mark.parametrize("name", PRESETS)
def test_every_preset_number_has_a_source(name):
    """Each effect with parameters says where they come from (TWIN.md: every effect carries per-parameter ``sources``)."""
    data = twin_to_dict(preset(name))
    effects = {
        **data["effects"],
        "sensor.bias": data["rig"]["sensor.bias"],
        "handle.connector_mass": data["rig"]["handle.connector_mass"],
    }
    for eid, eff in effects.items():
        params = [k for k in eff if k not in ("enabled", "description", "sources")]
        assert eff["description"], f"{name}: effect {eid} has no description"
        for prm in params:
            if eid == "kinematics.base_collision" and prm == "primitives":
                assert all(pr["name"] for pr in eff[prm])
            assert prm in eff["sources"], f"{name}: {eid}.{prm} has no source"
    for link in data["links"]:
        assert link["source"]
    assert data["gimbal_body"]["source"]
    floor = data["rig"]["accel_floor"]
    assert set(floor) - {"sources"} <= set(floor["sources"])


def test_touch_preset_kinematics_match_the_example_device():
    nominal = preset("touch").device.kinematics.model_dump()
    example = Device.model_validate(TOUCH_DEVICE).kinematics.model_dump()
    for a, b in zip(nominal["joints"], example["joints"]):
        assert a == b


@pytest.mark.parametrize("eid", ISSUE_EFFECT_IDS)
def test_disable_switches_one_effect_off_and_leaves_the_original(eid):
    tw = preset("touch")
    tw = set_param(tw, f"{eid}.enabled", True)
    off = disable(tw, eid)
    assert not off.on(eid)
    assert tw.on(eid)
    for other in ISSUE_EFFECT_IDS:
        if other != eid:
            assert off.on(other) == tw.on(other)


def test_set_param_forms():
    tw = preset("touch")
    a = set_param(tw, "friction.coulomb.torque_Nm", "0.02")  # CLI string, broadcast to every joint
    assert a.effects.friction_coulomb.torque_Nm == [0.02, 0.02, 0.02]
    b = set_param(tw, "friction.coulomb.torque_Nm[2]", 0.05)  # one entry
    assert b.effects.friction_coulomb.torque_Nm == tw.effects.friction_coulomb.torque_Nm[:2] + [0.05]
    c = set_param(tw, "drive.series_elasticity.stiffness_Nm_per_rad", "[10, 11, 12]")
    assert c.effects.drive_series_elasticity.stiffness_Nm_per_rad == [10, 11, 12]
    d = set_param(tw, "handle.connector_mass.mass_kg", 0.05)
    assert d.rig.connector_mass.mass_kg == 0.05
    e = set_param(tw, "links.1.mass_kg", 0.1)  # a structural field by dotted path
    assert e.links[1].mass_kg == 0.1
    f = set_param(tw, "drive.force_cutoff.enabled", "false")
    assert not f.on("drive.force_cutoff")
    assert tw.effects.friction_coulomb.torque_Nm != [0.02, 0.02, 0.02]  # original unchanged


@pytest.mark.parametrize(
    "path",
    ["friction.magic.torque_Nm", "friction.coulomb.nothing", "gravity", "links.9.mass_kg", "friction.coulomb.torque_Nm[7]"],
)
def test_set_param_unknown_is_e801(path):
    with pytest.raises(HaptifyError) as err:
        set_param(preset("touch"), path, 1.0)
    assert codes(err.value) == ["E801"]


def test_unknown_effect_and_preset_are_e801():
    with pytest.raises(HaptifyError) as err:
        disable(preset("touch"), "friction.magic")
    assert codes(err.value) == ["E801"]
    with pytest.raises(HaptifyError) as err:
        preset("phantom-premium")
    assert codes(err.value) == ["E801"]


@pytest.mark.parametrize(
    "path,value",
    [
        ("links.0.mass_kg", -1.0),
        ("friction.coulomb.torque_Nm", [0.1, 0.1]),  # wrong number of joints
        ("drive.force_cutoff.rearm_force_N", 100.0),  # above the trip level
        ("drive.coupling", [[1, 0, 0], [0, 1, 0], [0, 1, 0]]),  # singular
    ],
)
def test_invalid_values_are_e802(path, value):
    with pytest.raises(HaptifyError) as err:
        set_param(preset("touch"), path, value)
    assert set(codes(err.value)) == {"E802"}


def test_write_and_load_round_trip(tmp_path):
    tw = set_param(disable(preset("touch-x"), "gravity"), "friction.viscous.damping_Nms_per_rad", 1e-3)
    path = write_twin(tw, tmp_path / "twin.json")
    back = load_twin(path)
    assert back == tw
    raw = json.loads(path.read_text())
    assert raw["effects"]["gravity"]["enabled"] is False
    assert raw["format"] == "haptify-twin" and raw["twin_version"] == "1.0"


def test_bad_files_are_e802_with_pointers(tmp_path):
    bad = tmp_path / "bad.json"
    bad.write_text("{ not json", encoding="utf-8")
    with pytest.raises(HaptifyError) as err:
        load_twin(bad)
    assert codes(err.value) == ["E802"]
    data = twin_to_dict(preset("touch"))
    data["effects"]["gravity"]["g_m_per_s2"] = -1
    data["links"][0]["mass_kg"] = "heavy"
    with pytest.raises(HaptifyError) as err:
        twin_from_dict(data, file="x.json")
    pointers = {f.pointer for f in err.value.findings}
    assert {"/effects/gravity/g_m_per_s2", "/links/0/mass_kg"} <= pointers
    assert all(f.file == "x.json" for f in err.value.findings)


def test_twin_file_is_a_superset_of_the_device_description():
    fields = set(TwinFile.model_fields)
    assert "device" in fields and TwinFile.model_fields["device"].annotation is Device


@pytest.mark.parametrize("name", PRESETS)
def test_presets_validate_against_the_generated_json_schema(name):
    """The JSON Schema generated from TwinFile (what twin.schema.json holds) accepts the preset files."""
    import jsonschema

    from haptify_tools.twin.model import PRESET_DIR

    schema = TwinFile.model_json_schema(mode="validation", by_alias=True)
    data = json.loads((PRESET_DIR / f"{name}.json").read_text(encoding="utf-8"))
    jsonschema.validate(data, schema)
    bad = json.loads(json.dumps(data))
    bad["effects"]["drive.backlash"]["width_rad"] = "wide"
    with pytest.raises(jsonschema.ValidationError):
        jsonschema.validate(bad, schema)
