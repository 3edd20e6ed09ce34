"""What `thermo-ddp diagnose|identify` print: a short report read from the same result as the JSON (the
shipped simulated elbow recordings, whose concealed physics the testbed knows), the files written named,
the JSON only in the file or with `--json -` on stdout."""
import importlib.util
import json
from pathlib import Path

import pytest

from thermo_ddp._reports import MAX_LINES, diagnosis_report, fit_lines
from thermo_ddp.cli import main
from thermo_ddp.model.parameters import load_parameters

ELBOW = Path(__file__).resolve().parents[1] / "data" / "elbow"
RECORDINGS = [str(ELBOW / "static_3a.csv"), str(ELBOW / "biceps.csv")]
CONCEALED = {"friction_heating", "drive_heating"}  # PlantParameters().with_effects("both"): data/elbow/make_elbow.py


@pytest.fixture(scope="module")
def diagnosed(tmp_path_factory):
    folder = tmp_path_factory.mktemp("diagnose")
    paths = {"json": folder / "d.json", "model": folder / "improved.toml", "plot": folder / "d.png"}
    return paths


def test_diagnose_reports_the_concealed_physics_and_where_the_files_went(diagnosed, capsys):
    code = main(["diagnose", *RECORDINGS, "--json", str(diagnosed["json"]), "--write-model", str(diagnosed["model"]),
                 "--plot", str(diagnosed["plot"])])
    out = capsys.readouterr().out
    d = json.loads(diagnosed["json"].read_text())
    assert code == 0 and d["success"]
    assert {t["term"] for t in d["missing_physics"]} == CONCEALED     # the testbed's truth, named
    lines = out.splitlines()
    assert len(lines) <= MAX_LINES and not out.lstrip().startswith("{")
    for term in d["missing_physics"]:                                  # the report says what the JSON says
        line, = [ln for ln in lines if ln.strip().startswith(term["term"])
                 and "changes the prediction" in ln]
        assert f"{term['effect_k']:.3g} K" in line
    assert f"{d['validation']['rmse_after']:.3g} K" in out
    assert str(diagnosed["model"]) in out and "--write-model" in out and str(diagnosed["json"]) in out
    improved = load_parameters(diagnosed["model"])                     # what --write-model wrote loads
    assert improved.thermal.model != "one_node" or improved.thermal.values.get("drive_idle_w", 0) > 0


def test_json_dash_prints_the_json_on_stdout_and_the_report_on_stderr(diagnosed, capsys):
    assert main(["identify", *RECORDINGS, "--json", "-"]) == 0
    captured = capsys.readouterr()
    d = json.loads(captured.out)                                       # stdout is the JSON alone
    assert d["success"] and d["parameters"]
    assert "identification of 2 recordings" in captured.err
    for name, value in d["parameters"].items():                        # the report shows every parameter
        assert any(ln.split()[:2] == [name, f"{value:.5g}"] for ln in captured.err.splitlines()), name


def test_without_json_nothing_but_the_report(capsys, tmp_path):
    assert main(["identify", RECORDINGS[0]]) == 0
    out = capsys.readouterr().out
    assert "{" not in out and "rmse" in out and len(out.splitlines()) <= MAX_LINES
    assert list(tmp_path.iterdir()) == []


def test_a_long_report_is_cut_to_the_limit_and_says_so():
    d = {"success": True, "status": "ok", "message": "m", "physics": "thermal", "recordings": [f"r{i}" for i in range(50)],
         "rows": {"used": 10, "skipped": 0, "segments": 50},
         "not_determinable": [{"term": f"t{i}", "reason": "why: detail"} for i in range(60)]}
    text = fit_lines(diagnosis_report(d))
    assert len(text.splitlines()) == MAX_LINES and "more lines in the JSON" in text.splitlines()[-1]
    assert "r0, r1, r2 and 47 more" in text


def test_the_shipped_recording_is_small_and_regenerates_byte_for_byte(tmp_path):
    spec = importlib.util.spec_from_file_location("make_elbow", ELBOW / "make_elbow.py")
    make = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(make)
    for written in make.main(tmp_path):
        shipped = ELBOW / written.name
        assert shipped.stat().st_size < 300_000
        assert written.read_bytes() == shipped.read_bytes()


def test_mechanical_report_speaks_in_effort_units(emps_csv, capsys):
    assert main(["diagnose", str(emps_csv), "--physics", "mechanical"]) == 0
    out = capsys.readouterr().out
    assert "coulomb_friction" in out and len(out.splitlines()) <= MAX_LINES
    assert " K" not in out and "rmse" in out and "effort units" in out
