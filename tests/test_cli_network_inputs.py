"""Bad network files, scope sections and sensor maps through the CLI: one line naming the file, the field
and the value, exit 2, before any work."""
from __future__ import annotations

import copy

import numpy as np
import pytest

from conftest import DATA, ROOT
from thermo_ddp.cli import main
from thermo_ddp.model.parameters import load_parameters, packaged_parameter_file

NETWORK = {"model": "network", "ambient_c": 25.0, "sensor": "winding",
           "node": [{"name": "winding", "capacity_j_per_k": 200.0}, {"name": "tooth", "capacity_j_per_k": 400.0}],
           "link": [{"between": ["winding", "tooth"], "resistance_k_per_w": 0.5},
                    {"between": ["tooth", "ambient"], "resistance_k_per_w": 0.4}],
           "source": [{"kind": "copper", "split": {"winding": 1.0}},
                      {"kind": "iron_losses", "split": {"tooth": 0.7, "winding": 0.3}, "power_w": 50.0,
                       "ref_speed_rad_s": 500.0, "speed_exponent": 1.7}]}


def _text(thermal: dict, **scope) -> str:
    data = load_parameters(packaged_parameter_file("arm_left_4_joint")).to_dict()
    data = data | {"thermal": thermal, "limits": {"winding_max_c": 180.0, "safety_cutoff_c": 150.0}} | scope
    import tomli_w
    return tomli_w.dumps(data)


@pytest.fixture()
def recording(tmp_path):
    t = np.arange(0.0, 600.0, 2.0)
    path = tmp_path / "rec.csv"
    path.write_text("time_s,current_a,temperature_c,node_tooth_c\n" +
                    "".join(f"{x},{3.0},{25.0 + x / 100},{25.0 + x / 200}\n" for x in t))
    return path


def _exit_2(argv, capsys) -> str:
    assert main(argv) == 2
    captured = capsys.readouterr()
    err = captured.err.strip()
    assert err and "\n" not in err and "Traceback" not in err and not captured.out
    return err


def _network(change):
    thermal = copy.deepcopy(NETWORK)
    change(thermal)
    return thermal


@pytest.mark.parametrize("thermal, scope, field, words", [
    (_network(lambda t: t["node"][1].update(name="tooth-1")), {}, "thermal.node[1].name", "valid identifier"),
    (_network(lambda t: t["link"].pop(1)), {}, "thermal.link", "floating"),
    (_network(lambda t: t["source"][1]["split"].update(tooth=1.3, winding=-0.3)), {},
     "thermal.source.iron_losses.split.tooth", "expected 0 to 1"),
    (_network(lambda t: t["source"][1].update(split={"winding": -0.3, "tooth": 1.3})), {},
     "thermal.source.iron_losses.split.winding", "must be >= 0"),
    (_network(lambda t: t["source"][1]["split"].update(tooth=0.6)), {}, "thermal.source.iron_losses.split", "sum to 0.9"),
    (NETWORK, {"hardware": {"heat_sources": ["copper", "iron_loss"]}}, "hardware.heat_sources", "unknown heat source"),
    (NETWORK, {"uncertainty": {"thermal.link.winding-yoke.resistance_k_per_w": [0.1, 0.2]}}, "uncertainty",
     "names no value"),
])
def test_bad_parameter_file_exits_2_with_one_line(tmp_path, recording, capsys, thermal, scope, field, words):
    model = tmp_path / "bad.toml"
    model.write_text(_text(thermal, **scope))
    err = _exit_2(["validate", str(recording), "--model", str(model)], capsys)
    assert str(model) in err and f"{field} = " in err and words in err


def test_the_good_network_validates(tmp_path, recording, capsys):
    model = tmp_path / "good.toml"
    model.write_text(_text(NETWORK))
    assert main(["validate", str(recording), "--model", str(model)]) == 0
    assert "per sensor: winding" in capsys.readouterr().out


def test_a_sensor_column_missing_from_the_csv(tmp_path, capsys):
    columns = tmp_path / "map.toml"
    columns.write_text((ROOT / "examples" / "columns" / "paderborn_profile_24.toml").read_text()
                       + 'magnet = "rotor_magnet"\n')
    csv = DATA / "paderborn" / "profile_24.csv"
    err = _exit_2(["validate", str(csv), "--columns", str(columns), "--model",
                   str(packaged_parameter_file("paderborn_pmsm"))], capsys)
    assert str(csv) in err and "rotor_magnet = missing" in err and "sensors.magnet" in err and "row 1" in err


def test_a_sensor_with_an_invalid_node_name(tmp_path, capsys):
    columns = tmp_path / "map.toml"
    columns.write_text((ROOT / "examples" / "columns" / "paderborn_profile_24.toml").read_text()
                       .replace('tooth = "stator_tooth"', '"stator tooth" = "stator_tooth"'))
    err = _exit_2(["validate", str(DATA / "paderborn" / "profile_24.csv"), "--columns", str(columns), "--model",
                   str(packaged_parameter_file("paderborn_pmsm"))], capsys)
    assert str(columns) in err and "sensors = 'stator tooth'" in err and "identifier" in err


def test_a_contract_csv_with_a_bad_node_column(tmp_path, capsys):
    csv = tmp_path / "rec.csv"
    csv.write_text("time_s,current_a,temperature_c,node_tooth_c\n0,1,25,25\n1,1,25,400\n")
    err = _exit_2(["validate", str(csv), "--model", str(packaged_parameter_file("paderborn_pmsm"))], capsys)
    assert "node_tooth_c" in err and "row 3" in err and "kelvin" in err
