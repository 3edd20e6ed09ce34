"""Issue 14, each class of bad input the issue found: refused with one line and exit 2 before any work,
inputs and earlier outputs untouched; a run that fails says so (exit 1); no NaN, no traceback."""
import json
import math

import numpy as np
import pytest

from thermo_ddp import cli
from thermo_ddp.cli import main
from thermo_ddp.errors import InputError
from thermo_ddp.outputs import RUN_MARKER, Outputs, check_output_folder, write_folder_atomically


def run(argv, capsys):
    """(exit status, stderr) of ``thermo-ddp argv``; argparse's refusals raise SystemExit(2)."""
    try:
        code = main(argv)
    except SystemExit as exc:
        code = exc.code
    return code, capsys.readouterr().err.strip()


def refused(argv, capsys, *words):
    """``argv`` is refused: exit 2, one line naming ``words``."""
    code, err = run(argv, capsys)
    assert code == 2, err
    assert err and "\n" not in err and "Traceback" not in err
    for word in words:
        assert word in err, err
    return err


class WorkStarted(AssertionError):
    """A refusal must come before any work: reaching a solver, a simulation or an experiment fails the test."""


@pytest.fixture
def no_work(monkeypatch):
    def started(*args, **kwargs):
        raise WorkStarted("work started before the input was refused")
    for target in ("thermo_ddp.tasks.lift.make_solver", "thermo_ddp.model.actuated.ActuatedArm.simulate",
                   "thermo_ddp.studies.loop.record_experiments"):
        monkeypatch.setattr(target, started)


@pytest.fixture
def earlier(tmp_path):
    """An earlier output and an input file, with their contents."""
    out, rec = tmp_path / "earlier.json", tmp_path / "rec.csv"
    out.write_text('{"earlier": true}\n')
    rec.write_text("time_s,current_a,temperature_c\n0,1,30\n1,1,30.1\n2,1,30.2\n")
    return out, rec


# --- numbers: finite, in range, unit and limit in the message ------------------------------------
@pytest.mark.parametrize("argv, words", [
    (["demo", "--hold-s", "inf"], ["--hold-s", "finite", " s"]),
    (["demo", "--hold-s", "nan"], ["--hold-s", "finite"]),
    (["demo", "--hold-s", "1e9"], ["hold_s", "3600 s"]),
    (["demo", "--hold-s", "-5"], ["hold_s", ">= 0 s"]),
    (["demo", "--payload-kg", "1e6"], ["payload_kg", "100 kg"]),
    (["plan", "--hold-s", "inf"], ["--hold-s", "finite"]),
    (["plan", "--hold-s", "1e6"], ["hold_s", "3600 s"]),
    (["plan", "--payload-kg", "abc"], ["--payload-kg", "kg", "'abc'"]),
    (["plan", "--limit-c", "1e9"], ["limit_c", "°C"]),
    (["plan", "--limit-c", "200"], ["limit_c", "winding_max_c"]),
    (["compare", "--limits-c", "84", "300"], ["limit_c", "300"]),
    (["loop", "--hold-s", "1e6"], ["hold_s", "3600 s"]),
    (["loop", "--limits-c", "200"], ["limit_c", "winding_max_c"]),
])
def test_bad_numbers_refused_before_work(argv, words, capsys, no_work):
    refused(argv, capsys, *words)


# --- impossible parameter files --------------------------------------------------------------------
@pytest.mark.parametrize("old, new, key", [
    ("ambient_c = 26.0", "ambient_c = -500.0", "thermal.ambient_c"),
    ("resistance_ohm = 0.70", "resistance_ohm = 1e-300", "motor.resistance_ohm"),
    ("winding_max_c = 140.0", "winding_max_c = -300.0", "limits.winding_max_c"),
    ("gear_ratio = 100.0", "gear_ratio = nan", "motor.gear_ratio"),
])
def test_impossible_parameter_file_refused(old, new, key, tmp_path, elbow_file, capsys, no_work):
    bad = tmp_path / "bad.toml"
    bad.write_text(elbow_file.read_text().replace(old, new, 1))
    refused(["plan", "--model", str(bad)], capsys, str(bad), key)


# --- outputs: never an input, folders exist, formats known, earlier files kept ---------------------------
def test_json_onto_a_recording_refused(earlier, capsys, no_work):
    _, rec = earlier
    before = rec.read_bytes()
    refused(["identify", str(rec), "--json", str(rec)], capsys, "also an input")
    assert rec.read_bytes() == before


def test_json_onto_the_model_file_refused(tmp_path, elbow_file, capsys, no_work):
    model = tmp_path / "elbow.toml"
    model.write_text(elbow_file.read_text())
    refused(["plan", "--model", str(model), "--json", str(model)], capsys, "also an input")
    assert model.read_text() == elbow_file.read_text()


@pytest.mark.parametrize("plot", ["figure.xyz", "no/such/folder/figure.png", "."])
def test_bad_plot_refused_before_the_json_is_written(plot, earlier, tmp_path, capsys, no_work):
    out, _ = earlier
    refused(["plan", "--hold-s", "5", "--json", str(out), "--plot", str(tmp_path / plot)], capsys, "--plot")
    assert out.read_text() == '{"earlier": true}\n'


def test_json_into_a_missing_folder_refused(tmp_path, capsys, no_work):
    refused(["plan", "--json", str(tmp_path / "nope" / "x.json")], capsys, "folder does not exist")


def test_loop_out_naming_a_file_or_a_foreign_folder_refused(earlier, tmp_path, capsys, no_work):
    out, _ = earlier
    refused(["loop", "--short", "--out", str(out)], capsys, "is a file")
    foreign = tmp_path / "mine"
    foreign.mkdir()
    (foreign / "thesis.tex").write_text("precious")
    refused(["loop", "--short", "--out", str(foreign)], capsys, "not empty")
    assert (foreign / "thesis.tex").read_text() == "precious" and out.read_text() == '{"earlier": true}\n'


def test_failed_run_folder_leaves_the_earlier_run_untouched(tmp_path):
    def first(folder):
        (folder / "loop.json").write_text("first")
    target = tmp_path / "run"
    write_folder_atomically(target, first)
    assert check_output_folder("--out", target) == target  # an earlier run may be replaced...

    def failing(folder):
        (folder / "loop.json").write_text("half")
        raise RuntimeError("interrupted")
    with pytest.raises(RuntimeError):
        write_folder_atomically(target, failing)
    assert (target / "loop.json").read_text() == "first" and (target / RUN_MARKER).is_file()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["run"]  # ...and no half-written folder is left
    write_folder_atomically(target, lambda folder: (folder / "loop.json").write_text("second"))
    assert (target / "loop.json").read_text() == "second"


def test_commit_writes_all_outputs_or_none(tmp_path):
    a, b = tmp_path / "a.json", tmp_path / "b.png"
    a.write_text("old a")
    out = Outputs.check({"--json": a, "--plot": b}, figures=("--plot",))
    out.json("--json", {"new": 1})

    def broken_figure(path):
        raise RuntimeError("figure failed")
    out.figure("--plot", broken_figure)
    with pytest.raises(RuntimeError):
        out.commit()
    assert a.read_text() == "old a" and not b.exists()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.json"]  # no temporary left behind


def test_outputs_must_differ(tmp_path):
    with pytest.raises(InputError, match="also an input"):
        Outputs.check({"--json": tmp_path / "x.png", "--plot": tmp_path / "x.png"}, figures=("--plot",))


# --- exit status: 1 when the run failed, the JSON still written; NaN is never passed on -----------------
def test_identify_of_a_short_recording_exits_1_with_json(tmp_path, capsys):
    rec, out = tmp_path / "short.csv", tmp_path / "id.json"
    rec.write_text("time_s,current_a,temperature_c\n" + "".join(
        f"{10 * k},{2.0 if k < 15 else 0.0},{30 + 5 * (1 - math.exp(-k / 5)):.4f}\n" for k in range(30)))
    code, err = run(["identify", str(rec), "--json", str(out)], capsys)
    assert code == 1 and "Traceback" not in err
    d = json.loads(out.read_text())  # strict JSON: no NaN, no Infinity
    assert d["success"] is False and d["status"] and d["message"]


def test_non_finite_result_is_marked_failed(tmp_path, capsys):
    out = Outputs.check({"--json": tmp_path / "r.json"})
    staged = cli._result({"success": True, "rmse": float("nan"), "xs": np.array([1.0, np.inf])}, out)
    out.commit()
    d = json.loads((tmp_path / "r.json").read_text())
    assert staged == d and d["success"] is False and d["status"] == "non_finite_result"
    assert d["rmse"] is None and d["xs"] == [1.0, None] and "rmse" in d["message"]


def test_demo_says_when_the_motor_cannot_hold(capsys):
    assert main(["demo", "--payload-kg", "100", "--hold-s", "120"]) == 0
    out = capsys.readouterr().out
    assert "CANNOT HOLD" in out
    temps = [float(line.split()[4]) for line in out.splitlines() if line.strip().startswith("winding after")
             and "burns" not in line]
    assert all(t <= 400 for t in temps) and "burns" in out


def test_file_whose_motor_overheats_at_rest_refused(tmp_path, elbow_file, capsys, no_work):
    """Every value in range, but a 10 kW drive idle heat puts the resting winding at thousands of °C:
    the plan is refused before it is solved, not reported with absurd temperatures."""
    hot = tmp_path / "hot.toml"
    hot.write_text(elbow_file.read_text().replace("drive_idle_w = 23.0", "drive_idle_w = 1e4", 1))
    refused(["plan", "--model", str(hot), "--hold-s", "1"], capsys, str(hot), "at rest", "limit_c")


def test_json_onto_the_packaged_default_model_refused(elbow_file, capsys, no_work):
    before = elbow_file.read_bytes()
    refused(["plan", "--json", str(elbow_file)], capsys, "also an input")
    assert elbow_file.read_bytes() == before


@pytest.mark.parametrize("rows", [1, 2])
def test_mechanical_diagnosis_of_a_tiny_recording_refused(rows, tmp_path, capsys):
    rec = tmp_path / "tiny.csv"
    rec.write_text("time_s,position,velocity,effort\n" + "".join(f"{k},0,0,1\n" for k in range(rows)))
    refused(["diagnose", "--physics", "mechanical", str(rec)], capsys, str(rec), "too short")


def test_loop_limit_below_the_resting_winding_refused_before_the_experiments(tmp_path, capsys, no_work):
    out = tmp_path / "run"
    refused(["loop", "--short", "--limits-c", "30", "--out", str(out)], capsys, "limit_c", "at rest")
    assert list(tmp_path.iterdir()) == []  # no run folder, no temporary one


@pytest.mark.parametrize("content", [None, b"\x89PNG\r\n\x1a\n\xff\xfe binary"])
def test_unreadable_parameter_file_refused(content, tmp_path, capsys, no_work):
    model = tmp_path / "model.toml"
    if content is None:
        model.mkdir()  # a folder where the file should be
    else:
        model.write_bytes(content)
    refused(["plan", "--model", str(model)], capsys, str(model), "cannot read")


@pytest.mark.parametrize("option", ["--json", "--plot"])
def test_unusable_output_name_refused_before_work(option, tmp_path, capsys, no_work):
    refused(["plan", option, str(tmp_path / ("a" * 300 + ".png"))], capsys, option, "not a usable path")


def test_long_output_names_still_written(tmp_path):
    """A target name near the system's limit: the temporary file beside it must not be longer."""
    target = tmp_path / ("b" * 240 + ".json")
    out = Outputs.check({"--json": target})
    out.json("--json", {"ok": True})
    out.commit()
    assert json.loads(target.read_text()) == {"ok": True}


@pytest.mark.parametrize("name, value", [("THERMO_DDP_CACHE", "file"), ("THERMO_DDP_CACHE_MAX_MB", "lots")])
def test_bad_environment_refused(name, value, earlier, monkeypatch, capsys):
    _, rec = earlier
    monkeypatch.setenv(name, str(rec) if value == "file" else value)
    refused(["demo"], capsys, name)


def test_interrupted_run_writes_nothing(earlier, monkeypatch, capsys):
    out, _ = earlier

    def interrupted(*args, **kwargs):
        raise KeyboardInterrupt
    monkeypatch.setattr("thermo_ddp.tasks.lift.make_solver", interrupted)
    code, err = run(["plan", "--hold-s", "1", "--json", str(out)], capsys)
    assert code == 130 and "interrupted" in err and "\n" not in err
    assert out.read_text() == '{"earlier": true}\n' and sorted(p.name for p in out.parent.iterdir()) == [
        "earlier.json", "rec.csv"]


def test_too_many_limits_refused(capsys, no_work):
    refused(["compare", "--limits-c", *[str(84 + k) for k in range(9)]], capsys, "1 to 8")


def test_an_output_the_library_did_not_write_keeps_the_earlier_file(tmp_path):
    earlier = tmp_path / "d.png"
    earlier.write_bytes(b"earlier figure")
    out = Outputs.check({"--plot": earlier}, figures=("--plot",))
    assert out.temporary("--plot").is_file()  # handed to a library that, here, never draws
    assert out.commit() == [] and earlier.read_bytes() == b"earlier figure"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["d.png"]


def test_a_refusal_is_one_line_even_after_warnings(monkeypatch, capsys):
    import warnings

    def noisy(*args, **kwargs):
        warnings.warn("invalid value encountered in subtract", RuntimeWarning)
        raise InputError("rec.csv", "current_a", 1e300, "implausible")
    monkeypatch.setattr("thermo_ddp.studies.demo.hold_demo", noisy)
    assert refused(["demo"], capsys, "implausible").startswith("thermo-ddp: rec.csv")


@pytest.mark.parametrize("where", [".", ".."])
def test_loop_out_never_replaces_the_current_folder(where, tmp_path, monkeypatch, capsys, no_work):
    inner = tmp_path / "empty"
    inner.mkdir()
    monkeypatch.chdir(inner)
    refused(["loop", "--short", "--out", where], capsys, "current folder")
    assert inner.is_dir() and list(inner.iterdir()) == []


def test_outputs_get_the_permissions_of_a_plain_new_file(tmp_path):
    """Atomic writes go through a temporary file (owner-only when made); the result must not be."""
    import os
    import stat

    from thermo_ddp.outputs import write_text_atomically

    plain = tmp_path / "plain.txt"
    plain.write_text("x")
    written = write_text_atomically(tmp_path / "atomic.txt", "x")
    assert stat.S_IMODE(os.stat(written).st_mode) == stat.S_IMODE(os.stat(plain).st_mode)


def test_a_run_that_fails_midway_is_exit_1_one_line_not_bad_input(tmp_path, capsys, monkeypatch):
    """The loop's diagnosis failing after the experiments is a failed run (exit 1), not bad input (exit 2);
    the output folder is not created."""
    from types import SimpleNamespace

    from thermo_ddp.studies import loop

    failed = SimpleNamespace(success=False, status="model_does_not_fit",
                             message="no candidate explains these recordings")
    monkeypatch.setattr(loop, "diagnose_thermal", lambda *args, **kwargs: failed)
    monkeypatch.setattr(loop, "record_experiments", lambda robot, settings: ())
    out = tmp_path / "run"
    assert main(["loop", "--short", "--out", str(out)]) == 1
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "model_does_not_fit" in err and not out.exists()
