"""Parameter files: every joint's file loads; bad files give one clear error naming key and value."""
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from thermo_ddp.model.arm import LEFT_ARM
from thermo_ddp.errors import InputError
from thermo_ddp.model.parameters import dumps_parameters, load_parameters, parameters_from_dict, save_parameters

from thermo_ddp.model.parameters import packaged_parameter_file


@pytest.mark.parametrize("joint", LEFT_ARM)
def test_every_left_arm_joint_has_a_valid_file_with_sources(joint):
    p = load_parameters(packaged_parameter_file(joint))
    assert p.joint == joint
    data = p.to_dict()
    for section in ("motor", "thermal", "limits"):
        for key in data[section]:
            if key not in ("model", "friction_heating_fraction"):
                assert key in p.sources, f"{joint}: no source for {section}.{key}"


def test_round_trip(tmp_path, elbow_file):
    p = load_parameters(elbow_file)
    out = tmp_path / "copy.toml"
    out.write_text(dumps_parameters(p))
    assert load_parameters(out).to_dict() == p.to_dict()


def _broken(tmp_path, elbow_file, old, new):
    text = elbow_file.read_text()
    assert old in text
    path = tmp_path / "bad.toml"
    path.write_text(text.replace(old, new, 1))
    with pytest.raises(InputError) as err:
        load_parameters(path)
    msg = str(err.value)
    assert "\n" not in msg and str(path) in msg
    return msg


def test_missing_key(tmp_path, elbow_file):
    msg = _broken(tmp_path, elbow_file, "resistance_ohm = 0.70\n", "")
    assert "motor.resistance_ohm" in msg and "missing" in msg


def test_negative_capacity(tmp_path, elbow_file):
    msg = _broken(tmp_path, elbow_file, "winding_capacity_j_per_k = 40.0", "winding_capacity_j_per_k = -40.0")
    assert "thermal.winding_capacity_j_per_k" in msg and "-40.0" in msg and "> 0" in msg


def test_unit_typo_in_value(tmp_path, elbow_file):
    msg = _broken(tmp_path, elbow_file, "resistance_ohm = 0.70", 'resistance_ohm = "0.6 ohm"')
    assert "motor.resistance_ohm" in msg and "0.6 ohm" in msg and "number" in msg


def test_misspelt_key(tmp_path, elbow_file):
    msg = _broken(tmp_path, elbow_file, "resistance_ohm = 0.70", "resistance_ohms = 0.70")
    assert "motor.resistance_ohms" in msg


def test_unknown_thermal_model(tmp_path, elbow_file):
    msg = _broken(tmp_path, elbow_file, 'model = "two_node_drive"', 'model = "three_node"')
    assert "thermal.model" in msg and "three_node" in msg


def test_not_toml(tmp_path):
    path = tmp_path / "x.toml"
    path.write_text("[motor\n")
    with pytest.raises(InputError, match="not valid TOML"):
        load_parameters(path)


def test_replace_validates(elbow_file):
    p = load_parameters(elbow_file)
    assert p.replace("motor", resistance_ohm=0.8).motor.resistance_ohm == 0.8
    with pytest.raises(InputError, match="must be > 0"):
        p.replace("thermal", casing_capacity_j_per_k=0.0)
    with pytest.raises(InputError, match="unknown key"):
        p.replace("motor", resistance=1.0)


# --- physically impossible values: one line naming the file, the key and the value -----------------
@pytest.mark.parametrize("old, new, key, shown", [
    ("resistance_ohm = 0.70", "resistance_ohm = 1e-300", "motor.resistance_ohm", "1e-300"),
    ("winding_max_c = 140.0", "winding_max_c = -300.0", "limits.winding_max_c", "-300.0"),
    ("ambient_c = 26.0", "ambient_c = -500.0", "thermal.ambient_c", "-500.0"),
    ("ambient_c = 26.0", "ambient_c = 81.0", "thermal.ambient_c", "81.0"),
    ("safety_cutoff_c = 84.0", "safety_cutoff_c = 20.0", "limits.safety_cutoff_c", "20.0"),
    ("winding_max_c = 140.0", "winding_max_c = 26.0", "limits.winding_max_c", "26.0"),
    ("gear_ratio = 100.0", "gear_ratio = 0.0", "motor.gear_ratio", "0.0"),
    ("casing_capacity_j_per_k = 1200.0", "casing_capacity_j_per_k = 1e-300", "thermal.casing_capacity_j_per_k",
     "1e-300"),
    ("winding_casing_k_per_w = 0.9", "winding_casing_k_per_w = 1e9", "thermal.winding_casing_k_per_w", "1000000000.0"),
    ("drive_idle_w = 23.0", "drive_idle_w = -1.0", "thermal.drive_idle_w", "-1.0"),
    ("copper_alpha_per_k = 0.00393", "copper_alpha_per_k = 0.5", "motor.copper_alpha_per_k", "0.5"),
    ("resistance_ohm = 0.70", "resistance_ohm = nan", "motor.resistance_ohm", "nan"),
    ("resistance_ohm = 0.70", "resistance_ohm = inf", "motor.resistance_ohm", "inf"),
])
def test_impossible_value_is_refused_naming_file_key_and_value(tmp_path, elbow_file, old, new, key, shown):
    msg = _broken(tmp_path, elbow_file, old, new)
    assert key in msg and shown in msg


def test_every_catalogue_key_has_a_bound_with_a_reason():
    from thermo_ddp.model.catalogue import NETWORK_KEYS
    from thermo_ddp.model.parameters import (BOUNDS, LIMIT_KEYS, MOTOR_KEYS, THERMAL_KEYS, THERMAL_OPTIONAL)
    keys = {*MOTOR_KEYS, *LIMIT_KEYS, "ambient_c", *THERMAL_OPTIONAL, *NETWORK_KEYS,
            *(k for ks in THERMAL_KEYS.values() for k in ks)}
    assert keys == set(BOUNDS)
    assert all(b.low < b.high and b.reason for b in BOUNDS.values())
    assert all(BOUNDS[k].low <= v <= BOUNDS[k].high for k, v in THERMAL_OPTIONAL.items())


# --- optional [thermal] keys of the contract -----------------------------------------------------
def test_optional_thermal_keys_are_read_written_and_checked(tmp_path, elbow_file):
    text = elbow_file.read_text().replace('model = "two_node_drive"', 'model = "two_node_drive"\nsensor = "winding"\n'
                                          'friction_heat_node = "casing"\nfriction_heat_linear_w_s_per_rad = 0.4\n'
                                          'iron_loss_w = 2.0\niron_loss_ref_speed_rad_s = 3.0', 1)
    path = tmp_path / "extra.toml"
    path.write_text(text)
    p = load_parameters(path)
    assert p.thermal.sensor_node == "winding" and p.thermal.friction_node == "casing"
    assert p.thermal["friction_heat_linear_w_s_per_rad"] == 0.4 and p.thermal["iron_loss_speed_exponent"] == 2.0
    assert p.to_dict()["thermal"]["iron_loss_ref_speed_rad_s"] == 3.0
    assert "iron_loss_speed_exponent" not in p.to_dict()["thermal"]  # an absent key is not written
    out = tmp_path / "copy.toml"
    out.write_text(dumps_parameters(p))
    assert load_parameters(out).to_dict() == p.to_dict()
    msg = _broken(tmp_path, elbow_file, "drive_idle_w = 23.0", "drive_idle_w = 23.0\niron_loss_speed_exponent = 7.0")
    assert "thermal.iron_loss_speed_exponent" in msg and "7.0" in msg
    msg = _broken(tmp_path, elbow_file, "drive_idle_w = 23.0", 'drive_idle_w = 23.0\nsensor = "drive"')
    assert "thermal.sensor" in msg and "drive" in msg


def test_one_node_has_no_casing_to_measure(tmp_path, elbow_file):
    data = load_parameters(elbow_file).to_dict()
    data["thermal"] = {"model": "one_node", "ambient_c": 26.0, "capacity_j_per_k": 300.0, "resistance_k_per_w": 1.8,
                       "sensor": "casing"}
    with pytest.raises(InputError, match="thermal.sensor"):
        parameters_from_dict(data, "one.toml")
    del data["thermal"]["sensor"]
    assert parameters_from_dict(data).thermal.sensor_node == "winding"


# --- the writer: tomli-w, and loading what it writes gives the same parameters ------------------------
def _bounded(key):
    from thermo_ddp.model.parameters import BOUNDS
    b = BOUNDS[key]
    low = max(b.low, 1e-3 * b.high) if b.low > 0 else b.low
    return st.floats(low, b.high, allow_nan=False, allow_infinity=False)


@st.composite
def _parameter_sets(draw):
    from thermo_ddp.model.parameters import MOTOR_KEYS, THERMAL_KEYS, THERMAL_OPTIONAL
    model = draw(st.sampled_from(sorted(THERMAL_KEYS)))
    motor = {k: draw(_bounded(k)) for k in MOTOR_KEYS}
    motor["current_peak_a"] = max(motor["current_peak_a"], motor["current_nominal_a"])
    thermal = {"model": model, "ambient_c": draw(_bounded("ambient_c")),
               **{k: draw(_bounded(k)) for k in THERMAL_KEYS[model]}}
    optional = draw(st.lists(st.sampled_from(sorted(set(THERMAL_OPTIONAL) - set(thermal))), unique=True))
    thermal |= {k: draw(_bounded(k)) for k in optional}
    if model != "one_node":
        thermal |= draw(st.fixed_dictionaries({}, optional={"sensor": st.sampled_from(["casing", "winding"]),
                                                            "friction_heat_node": st.sampled_from(["casing"])}))
    limits = {k: thermal["ambient_c"] + draw(st.floats(0.5, 300.0)) for k in ("winding_max_c", "safety_cutoff_c")}
    sources = draw(st.dictionaries(st.sampled_from(sorted(MOTOR_KEYS)), st.text(max_size=30)))
    return {"joint": {"name": draw(st.text(min_size=1, max_size=20))}, "motor": motor, "thermal": thermal,
            "limits": limits, "sources": sources}


@settings(max_examples=60, deadline=None)
@given(_parameter_sets())
def test_written_files_load_back_unchanged(tmp_path_factory, data):
    p = parameters_from_dict(data, "drawn")
    path = tmp_path_factory.mktemp("rt") / "p.toml"
    save_parameters(p, path)
    back = load_parameters(path)
    assert back.to_dict() == p.to_dict() and back.thermal == p.thermal and back.motor == p.motor
