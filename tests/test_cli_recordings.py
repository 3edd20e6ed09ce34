"""`thermo-ddp identify|diagnose|validate`: contract JSON keys, options before or after recordings, column maps, exit codes."""
import json

import numpy as np
import pytest

from thermo_ddp.cli import main

DIAGNOSIS_KEYS = {"success", "status", "message", "physics", "recordings", "rows", "baseline", "mismatches",
                  "missing_physics", "not_determinable", "final", "validation", "unexplained"}
TERM_KEYS = {"term", "evidence", "parameters", "rmse", "p_value", "effect_k", "ci95", "collinear_with"}


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
    term, = d["missing_physics"]
    assert TERM_KEYS <= set(term) and term["p_value"] < 1e-3 and d["success"] and d["status"] == "ok"
    lo, hi = term["ci95"]["coulomb_friction"]
    assert lo < 20.3935 * 1.03 and hi > 20.3935 * 0.97  # the published value (Janot et al.) within 3 % of the interval
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
    from thermo_ddp.testing.testbed import PlantParameters, static_3a, static_4a

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


# ---------- real logs through column maps, --model, --write-model, validate ----------

from conftest import DATA, ROOT  # noqa: E402

MAPS = ROOT / "examples" / "columns"
PADERBORN = str(DATA / "paderborn" / "profile_24.csv")
UR3 = str(DATA / "ur3" / "ur3_cobotops.csv")
VALIDATE_KEYS = {"success", "status", "message", "model", "recordings", "rmse", "max_abs_error", "per_recording"}


def _one_line_exit_2(argv, capsys) -> str:
    assert main(argv) == 2
    err = capsys.readouterr().err.strip()
    assert err and "\n" not in err and "Traceback" not in err
    return err


def test_identify_with_map_and_model_writes_a_loadable_model_that_validate_reads(tmp_path, capsys):
    from thermo_ddp.model.parameters import load_parameters, packaged_parameter_file

    pmsm = str(packaged_parameter_file("paderborn_pmsm"))
    columns = str(MAPS / "paderborn_profile_24.toml")
    out, model = tmp_path / "id.json", tmp_path / "fitted.toml"
    assert main(["identify", PADERBORN, "--columns", columns, "--model", pmsm, "--json", str(out),
                 "--write-model", str(model)]) == 0
    d = json.loads(out.read_text())
    assert d["success"] and d["rows"] == {"used": 3003, "skipped": 0, "segments": 1}
    fitted = load_parameters(model)
    assert fitted.thermal["capacity_j_per_k"] == pytest.approx(d["parameters"]["capacity_j_per_k"])
    js, fig = tmp_path / "v.json", tmp_path / "v.png"
    assert main(["validate", PADERBORN, "--model", str(model), "--columns", columns, "--json", str(js),
                 "--plot", str(fig)]) == 0
    v = json.loads(js.read_text())
    assert VALIDATE_KEYS <= set(v) and v["success"] and v["model"] == str(model)
    one, = v["per_recording"]
    assert one["samples"] == 3003 and one["rmse"] == pytest.approx(v["rmse"]) and v["max_abs_error"] >= v["rmse"]
    assert fig.stat().st_size > 10_000


def test_write_model_equal_to_an_input_is_refused_before_work(tmp_path, capsys):
    from thermo_ddp.model.parameters import packaged_parameter_file

    model = tmp_path / "m.toml"
    text = packaged_parameter_file("paderborn_pmsm").read_text()
    model.write_text(text)
    err = _one_line_exit_2(["identify", PADERBORN, "--columns", str(MAPS / "paderborn_profile_24.toml"),
                            "--model", str(model), "--write-model", str(model)], capsys)
    assert "--write-model" in err and model.read_text() == text


@pytest.mark.parametrize("verb", ["identify", "diagnose", "validate"])
def test_missing_column_unknown_key_and_empty_cells_one_line_each(verb, tmp_path, capsys):
    model = ["--model", str(ROOT / "models" / "ur3_joint.toml")]
    missing = tmp_path / "missing.toml"
    missing.write_text('[time]\ncolumn = "Timestamp"\n[columns]\ntemperature_c = "Temperature_J9"\n'
                       'current_a = "Current_J1"\n[rows]\nskip_incomplete = true\n')
    err = _one_line_exit_2([verb, UR3, "--columns", str(missing), *model], capsys)
    assert "ur3_cobotops.csv row 1: Temperature_J9" in err and "missing.toml" in err
    unknown = tmp_path / "unknown.toml"
    unknown.write_text((MAPS / "ur3_joint1.toml").read_text().replace("skip_incomplete", "skip_incomplet"))
    err = _one_line_exit_2([verb, UR3, "--columns", str(unknown), *model], capsys)
    assert "unknown.toml" in err and "rows.skip_incomplet" in err
    strict = tmp_path / "strict.toml"
    strict.write_text((MAPS / "ur3_joint1.toml").read_text().replace("skip_incomplete = true", "skip_incomplete = false"))
    err = _one_line_exit_2([verb, UR3, "--columns", str(strict), *model], capsys)
    assert "ur3_cobotops.csv row 815: Temperature_J1 = : empty cell" in err  # data README: 54 rows with empty cells


def test_planning_refuses_a_motor_that_is_not_a_talos_joint(capsys):
    from thermo_ddp.model.parameters import packaged_parameter_file

    err = _one_line_exit_2(["plan", "--model", str(packaged_parameter_file("paderborn_pmsm"))], capsys)
    assert "joint.name = paderborn_pmsm" in err


def test_mechanical_refuses_a_motor_file(capsys):
    _one_line_exit_2(["identify", PADERBORN, "--physics", "mechanical", "--write-model", "x.toml"], capsys)


def test_validate_of_a_runaway_says_so_and_exits_1(tmp_path, capsys):
    """1000 A through a winding whose runaway current is ~50 A (eq. 8): the prediction overflows."""
    from thermo_ddp.model.parameters import load_parameters, packaged_parameter_file, save_parameters
    from thermo_ddp.recordings import Recording

    hot = load_parameters(packaged_parameter_file("paderborn_pmsm")).replace("thermal", resistance_k_per_w=10.0)
    model = tmp_path / "hot.toml"
    save_parameters(hot, model)
    t = np.arange(0.0, 30000.0, 10.0)
    rec = Recording(name="r", time_s=t, current_a=np.full_like(t, 1000.0), temperature_c=np.full_like(t, 20.0))
    out = tmp_path / "v.json"
    assert main(["validate", str(rec.to_csv(tmp_path / "r.csv")), "--model", str(model), "--json", str(out)]) == 1
    v = json.loads(out.read_text())
    assert (v["success"], v["status"], v["rmse"]) == (False, "not_finite", None)
