"""`thermo-ddp identify|diagnose`: contract JSON keys, options before or after recordings, exit codes."""
import json

import pytest

from thermo_ddp.cli import main

DIAGNOSIS_KEYS = {"physics", "recordings", "baseline", "mismatches", "missing_physics", "final", "validation",
                  "unexplained"}


@pytest.fixture(scope="module")
def emps(emps_csv):
    return str(emps_csv)


def test_identify_mechanical_on_emps(emps, tmp_path):
    out = tmp_path / "id.json"
    assert main(["identify", "--physics", "mechanical", emps, "--json", str(out)]) == 0
    params = json.loads(out.read_text())["parameters"]
    assert params["inertia"] == pytest.approx(95.1089, rel=0.03)  # published EMPS value (Janot et al. 2019)
    assert params["coulomb_friction"] == pytest.approx(20.3935, rel=0.03)


def test_diagnose_mechanical_on_emps_writes_contract_json_and_plot(emps, tmp_path):
    out, fig = tmp_path / "d.json", tmp_path / "d.png"
    assert main(["diagnose", emps, "--physics", "mechanical", "--json", str(out), "--plot", str(fig)]) == 0
    d = json.loads(out.read_text())
    assert DIAGNOSIS_KEYS <= set(d)
    assert d["physics"] == "mechanical"
    assert [m["term"] for m in d["missing_physics"]] == ["coulomb_friction"]
    assert d["validation"]["rmse_after"] < 0.65 * d["validation"]["rmse_before"]
    assert fig.stat().st_size > 10_000


@pytest.mark.parametrize("argv", [
    ["diagnose", "/no/such/file.csv", "--physics", "mechanical"],
    ["identify", "--physics", "kinetic", "x.csv"],
    ["identify", "--physics", "mechanical"],
])
def test_bad_input_exits_2_with_one_line(argv, capsys):
    with pytest.raises(SystemExit) as exc:
        code = main(argv)
        raise SystemExit(code)
    assert exc.value.code == 2
    err = capsys.readouterr().err.strip()
    assert err and "\n" not in err and "Traceback" not in err


def test_bad_csv_names_file_column_and_row(tmp_path, capsys):
    bad = tmp_path / "bad.csv"
    bad.write_text("time_s,position,effort\n0.0,0.1,1.0\n0.1,nan,1.0\n")
    assert main(["identify", str(bad), "--physics", "mechanical"]) == 2
    err = capsys.readouterr().err.strip()
    assert str(bad) in err and "position" in err and "row 3" in err


@pytest.fixture(scope="module")
def drive_heated_csvs(tmp_path_factory):
    """Two short recordings of the simulated elbow whose drive heats the motor (hidden from the model)."""
    from thermo_ddp.studies.testbed import PlantParameters, static_3a, static_4a

    plant = PlantParameters().with_effects("drive")
    folder = tmp_path_factory.mktemp("thermal")
    paths = []
    for make in (static_3a, static_4a):
        rec = make(params=plant, heating_s=1800.0, cooling_s=1800.0)
        path = folder / f"{rec.name}.csv"
        rec.to_csv(path)
        paths.append(str(path))
    return paths


def test_identify_thermal_cli(drive_heated_csvs, tmp_path):
    out = tmp_path / "id.json"
    assert main(["identify", *drive_heated_csvs, "--json", str(out)]) == 0  # --physics defaults to thermal
    d = json.loads(out.read_text())
    assert d["physics"] == "thermal" and d["success"]
    assert {"capacity_j_per_k", "resistance_k_per_w"} <= set(d["parameters"])


def test_diagnose_thermal_cli_finds_drive_heating_and_writes_a_loadable_parameter_file(drive_heated_csvs, tmp_path):
    from thermo_ddp.model.parameters import parameters_from_dict

    out = tmp_path / "d.json"
    assert main(["diagnose", "--physics", "thermal", *drive_heated_csvs, "--json", str(out)]) == 0
    d = json.loads(out.read_text())
    assert DIAGNOSIS_KEYS <= set(d)
    assert [m["term"] for m in d["missing_physics"]] == ["drive_heating"]
    assert {m["regime"] for m in d["mismatches"]} & {"idle", "cooling"}
    assert d["validation"]["rmse_after"] < 0.5 * d["validation"]["rmse_before"]
    improved = parameters_from_dict(d["parameter_file"]).thermal  # the drive's heat on the sensor node (contract)
    assert improved.model == "one_node" and improved["drive_idle_w"] > 1.0
