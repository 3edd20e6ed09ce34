"""The closed chain: recordings -> identification -> diagnosis -> improved model -> plan -> receding-horizon
execution on a plant with the robot's TRUE physics.

Oracles: the testbed's own numpy equations (thermal network rate, idle equilibrium) for the truth
plant; the project's ExtendedKalmanFilter for the sensor-node filter on a casing model; the testbed's
hidden truth (which effects are on) for the diagnosis; the true winding of the closed-loop plant for
the limit claims. The end-to-end run is short (30 min experiments, one limit, 20 s hold); the full
comparison at 84 and 140 °C runs in tests/test_notebook_loop.py.
"""
import csv
import json
import tomllib

import numpy as np
import pytest
from conftest import axes_without_units
from matplotlib.figure import Figure

from thermo_ddp.model.actuated import load_model
from thermo_ddp.model.arm import ELBOW
from thermo_ddp.errors import InputError
from thermo_ddp.cli import main
from thermo_ddp.outputs import write_folder_atomically
from thermo_ddp.recordings import column_map_from_dict, read_recordings
from thermo_ddp.studies.loop import (LoopSettings, claim, loop_files, mpc_settings, record_experiments, robot_parameters,
                                     truth_model, truth_parameters)
from thermo_ddp.mpc import ExtendedKalmanFilter, MPCSettings
from thermo_ddp.mpc.plant import Measurement
from thermo_ddp.model.parameters import load_parameters
from thermo_ddp.tasks.lift import plan_lift
from thermo_ddp.tasks.uncertainty import UncertaintySet
from thermo_ddp.testing.testbed import JOINT, PlantParameters, steady_state
from thermo_ddp.testing.thermal_replay import replay_winding_c
from thermo_ddp.testing.testbed.physics import thermal_network

def load_column_map_text(text: str):
    return column_map_from_dict(tomllib.loads(text), "robot_log.toml")


LIMIT_C = 84.0
# The robot logs in its own names and units (--columns): current in mA, speed in deg/s, the chain reads them back.
ROBOT_LOG = """
[time]
column = "stamp"
[columns]
current_a = { column = "motor_current_ma", scale = 0.001 }
temperature_c = "joint_temp"
position = "q"
velocity = { column = "dq_deg_s", scale = 0.017453292519943295 }
effort = "tau"
ambient_c = "room"
voltage_v = "motor_voltage"
"""


DRAWN: list = []


@pytest.fixture(scope="module")
def chain(tmp_path_factory):
    out = tmp_path_factory.mktemp("loop")
    columns = tmp_path_factory.mktemp("map") / "robot_log.toml"
    columns.write_text(ROBOT_LOG)
    save = Figure.savefig

    def record(fig, *args, **kwargs):  # the figures the run writes, kept to inspect their axes
        DRAWN.append(fig)
        return save(fig, *args, **kwargs)
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(Figure, "savefig", record)
        # the designed-experiment stage is off here: tests/test_experiment_design.py runs it on this robot
        table = loop_files(out, short=True, limits_c=(LIMIT_C,), hold_s=20.0, oracle=True, columns=columns,
                           experiment_s=None)
    return out, table


def test_every_figure_of_the_loop_has_units(chain):
    assert len(DRAWN) == 3  # diagnosis.png, loop.png, loop_summary.png
    for fig in DRAWN:
        assert axes_without_units(fig) == []


def test_settings_are_validated():
    with pytest.raises(InputError, match="unknown option"):
        LoopSettings.short(hold=3.0)
    with pytest.raises(InputError):
        LoopSettings(heating_s=100.0)
    with pytest.raises(InputError):
        LoopSettings(limits_c=())
    # the default window spans the whole task (lift 2 s + hold + lower 2 s + settle 0.5 s at 0.1 s)
    assert mpc_settings(LoopSettings(hold_s=60.0), 84.0, "x.toml").controller.horizon_knots == 645


@pytest.mark.parametrize("effects", ["both", "friction", "drive", "none"])
def test_truth_plant_thermal_rates_match_the_testbed_equations(effects):
    """The closed-loop plant's thermal ODE equals the testbed's independent numpy network, friction heat
    split between winding and casing included."""
    robot = PlantParameters(friction_to_winding=0.3).with_effects(effects)
    model = truth_model(robot, payload_kg=40.0)
    net = thermal_network(robot)
    rng = np.random.default_rng(0)
    for _ in range(20):
        temps = rng.uniform(25, 120, size=len(robot.node_names))
        q, v, i = rng.uniform(-2, 0), rng.uniform(-2, 2), rng.uniform(-15, 15)
        xdot = np.array(model.ode(np.concatenate([[q, v], temps]), [i], 26.0)).ravel()
        tau_f = robot.viscous_friction_nm_s_per_rad * v + robot.coulomb_friction_nm * np.tanh(
            v / robot.coulomb_smoothing_rad_s)
        want = net.rate(temps, i, abs(tau_f * v), 26.0)
        assert np.allclose(xdot[2:], want, rtol=1e-10, atol=1e-10)
    # the idle state (robot powered, motor unloaded) is the testbed's equilibrium: casing ~43 °C with the drive
    assert np.allclose(model.idle_temperatures(), steady_state(robot, 0.0, 0.0, 26.0), atol=1e-9)


def test_truth_parameter_file_carries_the_robot_values():
    robot = robot_parameters()
    p = truth_parameters(robot)
    assert p.joint == JOINT == ELBOW and p.thermal.model == "two_node_drive"
    assert p.thermal["winding_capacity_j_per_k"] == robot.winding_capacity_j_per_k
    assert p.thermal["drive_idle_w"] == robot.drive_idle_w and p.thermal["friction_heating_fraction"] == 1.0
    assert p.motor.coulomb_smoothing_rad_s == robot.coulomb_smoothing_rad_s
    assert truth_parameters(robot.with_effects("none")).thermal.model == "two_node"


def test_claim_tells_a_violation_from_wasted_margin():
    row = {"margin_c": 2.0, "cutoff_trips": 0, "closed_loop_hold_s": 10.0, "peak_true_winding_c": 82.0,
           "time_over_limit_s": 0.0, "peak_estimated_winding_c": 83.0}
    broken = claim(84.0, dict(row, margin_c=-11.0, peak_true_winding_c=95.0, time_over_limit_s=4.0), row)
    assert broken["original_violates"] and broken["improved_holds"] and broken["wasted_margin_c"] is None
    assert "breaks the limit (true winding 95.0 °C, 11.0 K over, for 4.0 s" in broken["statement"]
    careful = claim(84.0, dict(row, margin_c=20.0, closed_loop_hold_s=4.0), row)
    assert not careful["original_violates"] and careful["wasted_margin_c"] == 18.0 and careful["hold_gain_s"] == 6.0
    assert "conservative" in careful["statement"]
    failed = claim(84.0, row, dict(row, margin_c=-0.5))
    assert not failed["improved_holds"] and "FAILED" in failed["statement"]


def test_the_ekf_measures_the_winding_of_a_one_node_model(chain):
    out, _ = chain
    model = load_model((ELBOW,), payload_kg=40.0, parameter_files={ELBOW: out / "models" / f"{ELBOW}_original.toml"})
    assert model.networks[ELBOW].nodes == ("winding",)
    f = ExtendedKalmanFilter(model, MPCSettings())
    f.initialise(Measurement(0.0, np.array([-0.05]), np.zeros(1), np.zeros(1), np.array([43.0])))
    assert f.winding_c[0] == pytest.approx(43.0) and f.resistance_scale == 1.0
    for k in range(200):   # a hot sensor reading held: the estimate follows the measured node
        f.predict(np.zeros(1))
        f.update(Measurement(0.1 * k, np.array([-0.05]), np.zeros(1), np.zeros(1), np.array([60.0])))
    assert abs(f.winding_c[0] - 60.0) < 0.5


def test_chain_writes_recordings_models_figures_and_table(chain):
    out, table = chain
    for name in ("static_3a", "static_4a", "biceps", "winding_pulses"):
        with (out / "recordings" / f"{name}.csv").open() as handle:
            header = next(csv.reader(handle))
        assert header == ["stamp", "motor_current_ma", "joint_temp", "q", "dq_deg_s", "tau", "room", "motor_voltage"]
    # the logs, read through the map, are the robot's recordings (the testbed's own arrays)
    robot, settings = robot_parameters(), LoopSettings.short(limits_c=(LIMIT_C,), hold_s=20.0, oracle=True)
    biceps = next(r for r in record_experiments(robot, settings) if r.name == "biceps")
    read, = read_recordings([out / "recordings" / "biceps.csv"], load_column_map_text(ROBOT_LOG)).recordings
    for column in ("time_s", "current_a", "velocity", "temperature_c"):
        np.testing.assert_allclose(getattr(read, column), biceps.columns[column], rtol=1e-12, atol=1e-12)
    original = load_parameters(out / "models" / f"{ELBOW}_original.toml")
    improved = load_parameters(out / "models" / f"{ELBOW}_improved.toml")
    assert original.thermal.model == "one_node" and original.thermal["friction_heating_fraction"] == 0.0
    assert improved.thermal.model == "two_node_drive" and improved.thermal["friction_heat_linear_w_s_per_rad"] > 0.5
    assert json.loads((out / "loop.json").read_text()) == json.loads(json.dumps(table))
    for fig in ("loop.png", "loop_summary.png", "diagnosis.png"):
        assert (out / fig).stat().st_size > 10_000
    assert {r["model"] for r in table["rows"]} == {"original", "improved", "truth"}
    assert table["experiment"] is None and not list(out.glob("experiment.*"))   # the stage was off


def test_diagnosis_finds_the_robots_concealed_physics(chain):
    _, table = chain
    robot = robot_parameters()
    assert robot.friction_heating and robot.drive_heating
    assert {"friction_heating", "drive_heating"} <= set(table["diagnosis"]["missing_physics"])
    assert table["diagnosis"]["rmse_after"] < 0.5 * table["diagnosis"]["rmse_before"]


def test_the_improved_models_winding_node_is_close_to_the_robots(chain):
    """Known parameters (the testbed's hidden ones): the full-rate refit with voltage thermometry puts the
    winding node, which the casing sensor alone barely sees, near its true values."""
    _, table = chain
    vs = table["identified_vs_true"]
    assert vs["winding_capacity_j_per_k"]["identified"] == pytest.approx(vs["winding_capacity_j_per_k"]["true"], rel=0.12)
    assert vs["winding_casing_k_per_w"]["identified"] == pytest.approx(vs["winding_casing_k_per_w"]["true"], rel=0.04)
    assert vs["casing_ambient_k_per_w"]["identified"] == pytest.approx(vs["casing_ambient_k_per_w"]["true"], rel=0.06)
    assert any("thermometry" in n for n in table["improved_fit"]["notes"])


def test_improved_model_plans_and_its_closed_loop_keeps_the_true_winding_under_the_limit(chain):
    _, table = chain
    row = next(r for r in table["rows"] if r["model"] == "improved")
    assert row["thermal_model"] == "two_node_drive"
    assert row["plan_peak_winding_c"] <= LIMIT_C + 1e-3 and 0 < row["planned_hold_s"] <= 20.0
    assert row["closed_loop_status"] == "completed" and row["cutoff_trips"] == 0
    assert 0 <= row["margin_c"] and row["peak_true_winding_c"] <= LIMIT_C and row["time_over_limit_s"] == 0
    assert row["closed_loop_hold_s"] > 0


def test_original_model_breaks_the_limit_or_wastes_margin(chain):
    """The claim, checked against the true winding: the one-node model (sensor = winding, constant ambient)
    either exceeds the limit or holds less with more margin than the improved model."""
    _, table = chain
    orig, impr = (next(r for r in table["rows"] if r["model"] == m) for m in ("original", "improved"))
    claim = table["claims"][0]
    assert claim["original_violates"] == (orig["margin_c"] < 0)
    if claim["original_violates"]:
        assert orig["peak_true_winding_c"] > LIMIT_C and orig["time_over_limit_s"] > 0
        # the original planner believed it was safe: its winding estimate never approached the limit
        assert orig["peak_estimated_winding_c"] < LIMIT_C - 10
    else:
        assert orig["margin_c"] > impr["margin_c"] and orig["closed_loop_hold_s"] < impr["closed_loop_hold_s"]
    assert claim["improved_holds"]


def test_with_the_true_parameters_the_same_controller_keeps_a_small_margin(chain):
    """The oracle row (the robot's own parameter file as the planner's model): the closed loop then ends
    near the 1 K back-off, so the improved model's larger margin is the identification's, not the
    controller's."""
    _, table = chain
    impr, truth = (next(r for r in table["rows"] if r["model"] == m) for m in ("improved", "truth"))
    assert truth["closed_loop_status"] == "completed" and 0 <= truth["margin_c"] < 3.0
    # the closed loop cuts a hold in hold_step_s steps when re-solves turn infeasible: the oracle's hold is the
    # longer one up to one such step (careful motion on, re-solves with the nonmonotone Armijo: truth 11.6 s,
    # improved 11.5 s, margins 0.59 / 0.91 K; monotone, failed line searches cut the truth's hold to 10.8 s)
    step = MPCSettings().controller.hold_step_s
    assert truth["closed_loop_hold_s"] >= impr["closed_loop_hold_s"] - step and truth["margin_c"] <= impr["margin_c"]
    # what the voltage-informed identification leaves on the table: a few kelvin and a fraction of the hold
    assert impr["margin_c"] < 6.0 and impr["closed_loop_hold_s"] > 0.8 * truth["closed_loop_hold_s"]
    claim_ = table["claims"][0]
    assert claim_["oracle_hold_s"] == truth["closed_loop_hold_s"]
    assert claim_["improved_hold_share_of_oracle"] == pytest.approx(impr["closed_loop_hold_s"] / truth["closed_loop_hold_s"])


@pytest.mark.parametrize("body, words", [
    ('[time]\nstep_s = 1.0\n[columns]\ncurrent_a = "i"\ntemperature_c = "t"\n', ["time.step_s", "time column"]),
    ('[time]\ncolumn = "s"\n[columns]\ncurrent_a = { norm = ["i_d", "i_q"] }\ntemperature_c = "t"\n',
     ["columns.current_a.norm", "cannot be written back"]),
    ('[time]\ncolumn = "s"\n[columns]\ntemperature_c = "t"\n', ["columns.current_a", "diagnosis reads it"]),
    ('[time]\ncolumn = "s"\n[columns]\ncurrent_a = "i"\ntemperature_c = "i"\n', ["columns.temperature_c", "another"]),
    ('[time]\ncolumn = "s"\n[columns]\ncurrent_a = "i"\ntemperature_c = "t"\n[rows]\nsplit = 1\n', ["rows.split", "unknown"]),
])
def test_loop_refuses_a_column_map_it_cannot_log_by_before_any_work(tmp_path, capsys, monkeypatch, body, words):
    def no_work(*args, **kwargs):
        raise AssertionError("the experiments started")
    monkeypatch.setattr("thermo_ddp.studies.loop.record_experiments", no_work)
    columns = tmp_path / "map.toml"
    columns.write_text(body)
    assert main(["loop", "--short", "--out", str(tmp_path / "out"), "--columns", str(columns)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and str(columns) in err and all(w in err for w in words), err
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize("options, words", [
    (["--experiment-s", "0"], ["experiment_s = 0.0", "(0, 86400]"]),
    (["--experiment-s", "90000"], ["experiment_s = 90000.0", "(0, 86400]"]),
    (["--experiment-s", "600", "--no-experiment"], ["not allowed with argument"]),
])
def test_loop_refuses_a_bad_experiment_duration_before_any_work(tmp_path, capsys, monkeypatch, options, words):
    monkeypatch.setattr("thermo_ddp.studies.loop.record_experiments", lambda *a, **k: 1 / 0)
    try:
        code = main(["loop", "--short", "--out", str(tmp_path / "out"), *options])
    except SystemExit as parser_exit:   # argparse's refusal of the two options together
        code = parser_exit.code
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1 and all(w in err for w in words), err
    assert not (tmp_path / "out").exists()


def test_loop_refuses_a_column_map_inside_its_output_folder(tmp_path, capsys, monkeypatch):
    """An earlier run's folder is replaced by the next run: a map kept in it would be lost."""
    monkeypatch.setattr("thermo_ddp.studies.loop.record_experiments", lambda *a, **k: 1 / 0)
    write_folder_atomically(tmp_path / "out", lambda folder: (folder / "map.toml").write_text(ROBOT_LOG))
    columns = tmp_path / "out" / "map.toml"
    assert main(["loop", "--short", "--out", str(tmp_path / "out"), "--columns", str(columns)]) == 2
    assert "inside the output folder" in capsys.readouterr().err and columns.read_text() == ROBOT_LOG


def test_the_identified_intervals_give_a_robust_plan(chain):
    """Issue 26 with the intervals of a real identification: the improved file's [uncertainty] (the refit's 95 %
    intervals) gives a robust hold, reported with the nominal one; 200 motors drawn in those intervals and
    replayed independently (scipy, casing at the plan's reading) stay within 0.5 K of the limit under it."""
    out, _ = chain
    path = out / "models" / f"{ELBOW}_improved.toml"
    params = load_parameters(path)
    intervals = params.scope.uncertainty
    assert len(intervals) >= 5 and all(np.isfinite(hi) and lo < hi for lo, hi in intervals.values())
    assert all(lo <= params.value(k) <= hi for k, (lo, hi) in intervals.items())
    plan = plan_lift(40.0, LIMIT_C, parameter_file=str(path), uncertainty="file")
    r = plan.robust.to_dict()
    assert r["uncertainty"] == "file" and r["worst_winding_c"] <= LIMIT_C + 0.1
    assert 0 < plan.achieved_hold_s <= r["nominal_hold_s"] and "nominal motor alone" in plan.message
    uset = UncertaintySet.from_file(params, path)
    motors = [uset.parameters(params, th) for th in uset.sample(np.random.default_rng(0), 200)]
    casing = {"casing": float(plan.series("casing_c")[0, 0])}
    w = replay_winding_c(motors, plan.time_s, plan.us, plan.series("v_rad_s"), casing)
    assert w.max() <= LIMIT_C + 0.5
