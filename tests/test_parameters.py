"""Parameter files: every joint's file loads; bad files give one clear error naming key and value."""
import pytest

from thermo_ddp.model.arm import LEFT_ARM
from thermo_ddp.errors import InputError
from thermo_ddp.model.parameters import dumps_parameters, load_parameters

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
