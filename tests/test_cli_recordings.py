"""`thermo-ddp identify|diagnose`: contract JSON keys, options before or after recordings, exit codes."""
import json

import pytest

from thermo_ddp.cli import main

DIAGNOSIS_KEYS = {"physics", "recordings", "baseline", "mismatches", "missing_physics", "final", "validation",
                  "unexplained"}


@pytest.fixture(scope="module")
def emps(shared_dir):
    return str(shared_dir / "data" / "emps" / "emps_estimation.csv")


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
