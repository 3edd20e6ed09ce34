"""Designed experiments (thermo_ddp.tasks.experiment): the experiment the DDP plans from a diagnosis, run on the
testbed's hidden truths (thermo_ddp.testing.testbed.truths) and diagnosed again with the passive recording.

Oracles: the truth's concealed terms and friction-heat values (c1 |v| + c2 v^2), its true winding temperature,
the request's duration and the joint's URDF range and speed limit.
"""
from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest

from thermo_ddp.diagnose.thermal import diagnose_thermal
from thermo_ddp.identify.thermal import FRICTION_KEYS
from thermo_ddp.tasks.experiment import ExperimentSettings, design_experiment
from thermo_ddp.tasks.experiment_motion import joint_bounds
from thermo_ddp.identify.thermal import load_joint_parameters
from thermo_ddp.studies.experiment_loop import experiment_stage, undetermined
from thermo_ddp.studies.loop import LoopSettings, record_experiments, robot_parameters
from thermo_ddp.tasks.experiment_motion import programme
from thermo_ddp.testing.testbed import LOGGED_COLUMNS, PlantParameters, programmed
from thermo_ddp.testing.testbed.truths import family_case, run_programme

HEAT = {"friction_heating", "drive_heating", "iron_losses", "copper_resistance"}
LIMIT_C, DURATION_S = 84.0, 3600.0
MEASUREMENT = {"noise_c": 0.05, "sample_s": 2.0}


def passive(name: str):
    """The family's passive session (thermo_ddp.testing.testbed.truths.FAMILIES) on the class truth."""
    return family_case(name, np.random.default_rng(1), **MEASUREMENT)


def designed_and_rediagnosed(name: str, before=None):
    """The family's design (from ``before``, the passive diagnosis, when known), run on the truth, diagnosed again."""
    truth, rec = passive(name)
    design = design_experiment([rec], settings=ExperimentSettings(duration_s=DURATION_S, limit_c=LIMIT_C,
                                                                  progress=False), diagnosis=before)
    assert design.success and design.status == "designed", design.message
    rows = design.programme()
    run, temps = run_programme(truth, rows, np.random.default_rng(2), name="designed", **MEASUREMENT)
    return truth, design, rows, temps, diagnose_thermal([rec, run])


def check_settled(truth, design, rows, temps, after):
    # safety and the request: the true winding under the limit, the duration, the joint's range and speed
    assert temps[:, 0].max() <= LIMIT_C
    assert rows["time_s"][-1] <= DURATION_S and design.duration_s <= DURATION_S
    lo, hi, vmax = joint_bounds(load_joint_parameters(None), 0.0)
    assert lo <= rows["position"].min() and rows["position"].max() <= hi
    assert np.abs(rows["velocity"]).max() <= vmax and rows["velocity"][-1] == 0.0
    acceleration = np.abs(np.diff(rows["velocity"]) / np.diff(rows["time_s"]))
    assert acceleration.max() <= design.settings.acceleration_rad_s2 * (1 + 1e-9)
    assert design.peak_winding_c <= LIMIT_C + 0.05
    # the exact heat terms, every named parameter within +-50 %, friction heat within 40 % of the truth
    assert after.status == "ok"
    assert set(after.missing_physics) & HEAT == set(truth.concealed) & HEAT
    for term in after.to_dict()["missing_physics"]:   # values held at the file's are not estimated: not judged
        for key, value in ((k, v) for k, v in term["parameters"].items() if k not in term["held"]):
            low, high = term["ci95"][key]
            assert (high - low) / 2 <= 0.5 * abs(value), (term["term"], key, value, low, high)
    if "friction_heating" in truth.concealed:
        fit = after.final_fit.parameters
        true = (truth.friction_linear_w_s_per_rad, truth.friction_quadratic_w_s2_per_rad2)
        for key, value in zip(FRICTION_KEYS, true):
            assert abs(fit[key] - value) <= 0.4 * value, (key, fit[key], value)


def test_designed_experiment_settles_friction_heat_seen_at_one_speed():
    _, rec = passive("friction_one_speed")
    before = diagnose_thermal(rec)
    assert before.missing_physics == ["friction_heating"]
    assert not before.final_fit.identifiable(FRICTION_KEYS[0])   # one speed: c1 and c2 not separable
    truth, design, rows, temps, after = designed_and_rediagnosed("friction_one_speed", before)
    assert design.targets == ("friction_heating",) and design.predicted_separation_k["friction_heating"] > 0
    assert design.to_dict()["not_determinable"] == []   # the design predicts every value pinned: and it is
    check_settled(truth, design, rows, temps, after)


@pytest.mark.slow
def test_designed_experiment_settles_friction_heat_never_excited():
    truth, design, rows, temps, after = designed_and_rediagnosed("friction_never_excited")
    assert design.targets[0] == "friction_heating"
    check_settled(truth, design, rows, temps, after)


@pytest.mark.slow   # the passive half is covered by test_motion_only_under_load_leaves_friction_heat_undetermined
def test_designed_experiment_settles_drive_and_friction_heat_seen_only_while_moving():
    truth, design, rows, temps, after = designed_and_rediagnosed("both_only_moving")
    assert set(after.missing_physics) == {"friction_heating", "drive_heating"}   # exact terms: this holds
    check_settled(truth, design, rows, temps, after)


def test_motion_only_under_load_leaves_friction_heat_undetermined():
    """The passive session of 'drive + friction heat seen only while moving': the joint carries current only while it
    moves, so the friction heat reads as a larger thermal resistance.  The diagnosis names the drive heat (its idle
    loss identifiable; its i^2 loss, the copper's twin on one node, held at the file's value and listed as held)
    and lists friction heat as undetermined, seen in one regime, instead of absorbing it silently."""
    _, rec = passive("both_only_moving")
    before = diagnose_thermal(rec)
    assert before.status == "ok" and before.missing_physics == ["drive_heating"]
    term = before.to_dict()["missing_physics"][0]
    assert term["held"] == ["drive_loss_w_per_a2"] and "drive_loss_w_per_a2" not in term["ci95"]
    assert before.final_fit.identifiable("drive_idle_w")
    assert any(n["term"] == "friction_heating" and "one regime" in n["reason"] for n in before.not_determinable)
    assert "friction_heating" in undetermined(before)


def test_a_resting_temperature_apart_is_no_divergence():
    """Two explanations that differ only in a steady heat (the drive's idle loss + 3 W) rest R_th * 3 W apart (the
    one-node steady state, oracle); that offset is no divergence: zero on a programme at rest, and under current
    only the copper's temperature coefficient separates them (R alpha dT i^2, far below the offset)."""
    from thermo_ddp.identify.thermal import ThermalModel, start_values
    from thermo_ddp.tasks.experiment import _build
    from thermo_ddp.tasks.experiment_rivals import Explanations, Rival, Target
    params = load_joint_parameters(None)
    terms = ("drive_heating",)
    values = start_values(params, terms)
    reference = Rival("reference", terms, values)
    warmer = Rival("warmer", terms, values | {"drive_idle_w": values["drive_idle_w"] + 3.0})
    model = ThermalModel(params, terms, {"drive_loss_w_per_a2": values["drive_loss_w_per_a2"]})
    expl = Explanations(reference, (Target("drive_heating", "test", (warmer,)),), (), model)
    design = _build(expl, 0.05, LIMIT_C, 25.0, np.array([5.0, 2.0]), ExperimentSettings(duration_s=1800.0), 1.0)
    offset = np.diff(design.sensors(design.x0[None, :])[0])[0]
    assert offset == pytest.approx(3.0 * values["resistance_k_per_w"], rel=0.05)
    rest = np.zeros((design.mm.horizon, 2))
    assert np.abs(design.divergences(design.rollout(rest))).max() < 1e-9
    loaded = np.column_stack([np.full(design.mm.horizon, 3.0), np.zeros(design.mm.horizon)])
    assert 0 < np.abs(design.divergences(design.rollout(loaded))).max() < 0.1 * offset


def test_predicted_half_widths_are_the_cramer_rao_bound_and_a_blind_value_is_unbounded():
    """half_widths: Z95 sqrt(diag((J'J)^-1)) of the full least-squares problem (values and each segment's offset,
    numpy's inverse as the oracle); a value no row sees is unbounded."""
    from thermo_ddp.identify.fit_report import Z95
    from thermo_ddp.tasks.experiment_information import half_widths
    rng = np.random.default_rng(0)
    blocks = [rng.normal(size=(40, 3)), rng.normal(size=(30, 3))]   # 2 values + the segment's offset
    j = np.zeros((70, 4))
    j[:40, :2], j[:40, 2], j[40:, :2], j[40:, 3] = blocks[0][:, :2], blocks[0][:, 2], blocks[1][:, :2], blocks[1][:, 2]
    oracle = Z95 * np.sqrt(np.diag(np.linalg.inv(j.T @ j))[:2])
    assert half_widths(blocks) == pytest.approx(oracle, rel=1e-9)
    blind = [np.column_stack([b[:, :1], np.zeros(len(b)), b[:, 2:]]) for b in blocks]
    widths = half_widths(blind)
    assert np.isfinite(widths[0]) and np.isinf(widths[1])


def test_a_value_no_start_pins_is_listed_not_determinable():
    """undeterminable: a named value whose predicted half-width exceeds 50 % on every start's design is listed (with
    the smallest); one start that pins it within 50 % is enough to demand it."""
    from thermo_ddp.identify.thermal import ThermalModel, start_values
    from thermo_ddp.tasks.experiment_information import undeterminable
    from thermo_ddp.tasks.experiment_rivals import Explanations, Rival, Target
    params = load_joint_parameters(None)
    terms = ("drive_heating",)
    values = start_values(params, terms)
    reference = Rival("reference", terms, values)
    warmer = Rival("warmer", terms, values | {"drive_idle_w": values["drive_idle_w"] * 1.5})
    model = ThermalModel(params, terms, {"drive_loss_w_per_a2": values["drive_loss_w_per_a2"]})
    expl = Explanations(reference, (Target("drive_heating", "test", (warmer,)),), (), model)
    idle = list(model.keys).index("drive_idle_w")
    loose, tight = np.full(len(model.keys), 0.1), np.full(len(model.keys), 0.1)
    loose[idle], tight[idle] = 0.9, 0.3
    listed = undeterminable(expl, [loose, 2 * loose])
    assert [(u["term"], u["key"]) for u in listed] == [("drive_heating", "drive_idle_w")]
    assert listed[0]["predicted_half_width"] == pytest.approx(0.9)
    assert undeterminable(expl, [loose, tight]) == () and undeterminable(expl, []) == ()


def test_a_truth_with_nothing_missing_names_nothing():
    _, rec = passive("nothing_missing")
    before = diagnose_thermal(rec)
    design = design_experiment([rec], settings=ExperimentSettings(progress=False), diagnosis=before)
    assert design.success and design.status == "nothing_undetermined" and design.targets == ()
    assert design.to_dict()["predicted_separation_k"] == {} and design.to_dict()["duration_s"] == 0.0
    # the loop's stage runs nothing on the robot and keeps the diagnosis
    def never(run):
        raise AssertionError("an experiment ran")
    stage, sources = experiment_stage(PlantParameters(), [rec], before, ExperimentSettings(progress=False), never)
    assert stage.run is None and stage.after is before and sources == [rec]
    assert stage.to_dict()["ran"] is False and "nothing_undetermined" in stage.report_lines()[0]


def test_the_testbed_elbow_runs_a_programme_at_its_current_and_speed():
    """Oracles: the programme's own current and velocity, and the testbed's friction power F_c |v| + b v^2."""
    plant = PlantParameters()
    lo, hi, _ = joint_bounds(load_joint_parameters(None), 0.2)
    rows = programme(60.0, np.array([0.0, 3.0, 3.0, 5.0, 0.0]), np.array([0.0, 0.0, 2.0, 0.5, 0.0]), (lo, hi),
                     10.0, 0.1)
    run = programmed(rows, params=plant, name="programme", seed=3)
    truth = run.truth
    k = np.searchsorted(rows["time_s"], truth.time_s, side="right") - 1
    np.testing.assert_allclose(truth.current_a, rows["current_a"][k], atol=1e-9)
    v = np.interp(truth.time_s, rows["time_s"], rows["velocity"])
    np.testing.assert_allclose(run.columns["velocity"], v, atol=0.05)   # the sensor's noise
    smooth = np.tanh(v / plant.coulomb_smoothing_rad_s)
    power = np.abs((plant.viscous_friction_nm_s_per_rad * v + plant.coulomb_friction_nm * smooth) * v)
    np.testing.assert_allclose(truth.friction_w, power, atol=1e-9)
    assert truth.time_s[-1] <= rows["time_s"][-1] and truth.phases[-1][3] == pytest.approx(rows["time_s"][-1])


@pytest.mark.slow
def test_the_loop_stage_designs_runs_on_the_elbow_and_diagnoses_again():
    """``thermo-ddp loop``'s stage on its robot (short recordings): the drive's and friction heat's values are
    undetermined; the designed 15 min run under 84 °C on the robot's true winding; friction heat then within 40 %
    of the robot's (F_c |v| + b v^2: c1 = F_c, c2 = b)."""
    settings = LoopSettings.short(limits_c=(LIMIT_C,), heating_s=900.0, cooling_s=900.0, experiment_s=900.0)
    robot = robot_parameters()
    sources = [r.to_recording(LOGGED_COLUMNS) for r in record_experiments(robot, settings)]
    before = diagnose_thermal(sources)
    assert {"friction_heating", "drive_heating"} <= set(undetermined(before))
    design = ExperimentSettings(duration_s=settings.experiment_s, limit_c=LIMIT_C, progress=False)
    stage, more = experiment_stage(robot, sources, before, design, lambda run: run.to_recording(LOGGED_COLUMNS))
    assert stage.design.designed and len(more) == len(sources) + 1
    assert stage.true_peak_winding_c <= LIMIT_C and stage.run.time_s[-1] <= settings.experiment_s
    assert {"friction_heating", "drive_heating"} <= set(stage.after.missing_physics)
    fit = stage.after.final_fit.parameters
    for key, true in zip(FRICTION_KEYS, (robot.coulomb_friction_nm, robot.viscous_friction_nm_s_per_rad)):
        assert abs(fit[key] - true) <= 0.4 * true, (key, fit[key], true)
    lines = stage.report_lines()
    assert "designed 15 min" in lines[0] and "true winding peak" in lines[1] and "diagnosed again" in lines[2]
    assert json.dumps(stage.to_dict())


def write_csv(rec, path):
    columns = ("time_s", "current_a", "temperature_c", "velocity", "ambient_c")
    np.savetxt(path, np.column_stack([getattr(rec, c) for c in columns]), delimiter=",", header=",".join(columns),
               comments="")
    return str(path)


@pytest.mark.parametrize("options, message", [
    (["--duration-s", "0"], "duration_s = 0.0: must be in (0, 86400]"),
    (["--duration-s", "90000"], "duration_s = 90000.0: must be in (0, 86400]"),
    (["--limit-c", "40"], "not above the winding's temperature at rest, 43.0 °C"),
    (["--limit-c", "150"], "above the winding's rated maximum"),
])
def test_bad_requests_get_one_line_and_exit_2(tmp_path, capsys, options, message):
    from thermo_ddp.cli import main
    t = np.arange(0.0, 30.0, 10.0)
    rec = type("R", (), {"time_s": t, "current_a": 0 * t, "temperature_c": 30 + 0 * t, "velocity": 0 * t,
                         "ambient_c": 25 + 0 * t})
    csv = write_csv(rec, tmp_path / "rec.csv")
    assert main(["design-experiment", csv, "--out", str(tmp_path / "exp.csv"), *options]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and message in err
    assert main(["design-experiment", csv, "--out", csv]) == 2
    assert "is also an input" in capsys.readouterr().err
    assert not (tmp_path / "exp.csv").exists()


def test_cli_says_so_when_nothing_is_undetermined_and_writes_no_experiment(tmp_path, capsys):
    from thermo_ddp.cli import main
    _, rec = passive("nothing_missing")
    csv = write_csv(rec, tmp_path / "rec.csv")
    code = main(["design-experiment", csv, "--out", str(tmp_path / "exp.csv"), "--plot", str(tmp_path / "exp.png"),
                 "--json", str(tmp_path / "exp.json")])
    assert code == 0 and "nothing undetermined" in capsys.readouterr().out
    assert not (tmp_path / "exp.csv").exists() and not (tmp_path / "exp.png").exists()
    out = json.loads((tmp_path / "exp.json").read_text())
    assert out["status"] == "nothing_undetermined" and out["targets"] == [] and out["success"]


@pytest.mark.slow
def test_cli_writes_the_experiment_the_testbed_runs(tmp_path):
    _, rec = passive("friction_one_speed")
    csv = write_csv(rec, tmp_path / "rec.csv")
    exp, js = tmp_path / "exp.csv", tmp_path / "exp.json"
    done = subprocess.run([sys.executable, "-m", "thermo_ddp.cli", "design-experiment", csv, "--out", str(exp),
                           "--json", str(js), "--plot", str(tmp_path / "exp.png")], capture_output=True, text=True)
    assert done.returncode == 0, done.stderr
    out = json.loads(js.read_text())
    assert out["status"] == "designed" and out["targets"] == ["friction_heating"]
    assert set(out) >= {"success", "status", "message", "targets", "duration_s", "peak_winding_c", "limit_c",
                        "predicted_separation_k"}
    table = np.genfromtxt(exp, delimiter=",", names=True)
    assert table.dtype.names == ("time_s", "current_a", "position", "velocity")
    assert table["time_s"][-1] <= out["duration_s"] <= DURATION_S and out["peak_winding_c"] <= LIMIT_C + 0.05
    assert (tmp_path / "exp.png").stat().st_size > 0


@pytest.mark.slow
def test_the_loop_diagnoses_designs_runs_and_diagnoses_again():
    from thermo_ddp.studies.experiment_loop import close_the_loop
    truth, rec = passive("both_only_moving")
    loop = close_the_loop([rec], truth, rounds=2, settings=ExperimentSettings(limit_c=LIMIT_C, progress=False))
    assert loop.success and loop.rounds[0].design.designed
    assert loop.rounds[0].named == ("drive_heating",)      # the passive recording alone misses the friction heat
    for r in loop.rounds:
        assert r.true_peak_winding_c is None or r.true_peak_winding_c <= LIMIT_C
        assert r.design.duration_s <= DURATION_S
    assert set(loop.final.missing_physics) == {"friction_heating", "drive_heating"}
    assert "round 1" in loop.report() and json.dumps(loop.to_dict())
