"""The sweep on Dask: a LocalCluster of two worker processes gives the serial numbers seed for seed, a
worker killed mid-sweep loses no run, a failing task is recorded (not dropped), and the CLI writes the
Sweep JSON of the contract."""
import json
import os
import signal
import threading
import time

import pytest

from thermo_ddp.cli import main
from thermo_ddp.studies.engine import EngineSettings, dask_client, map_tasks
from thermo_ddp.studies.sweep import draw, robustness_sweep, run_seeds, sweep_run

COMPARED = ("max_winding_c", "achieved_hold_s", "nominal_hold_s", "margin_c", "violations", "cutoff_trips",
            "fallbacks", "draw")


def assert_same_runs(a, b):
    assert [r["seed"] for r in a] == [r["seed"] for r in b]
    for x, y in zip(a, b):
        for key in COMPARED:
            assert x[key] == y[key], (x["seed"], key, x[key], y[key])


@pytest.fixture(scope="module")
def serial():
    return robustness_sweep(4, seed=3, short=True, engine=None, progress=False)


def test_seeds_of_a_longer_sweep_extend_a_shorter_one():
    assert run_seeds(3, 200)[:4] == run_seeds(3, 4)
    assert len(set(run_seeds(3, 200))) == 200 and run_seeds(3, 4) != run_seeds(4, 4)


def test_local_cluster_equals_serial_seed_for_seed(serial):
    assert serial.success and serial.summary()["violations"] == 0
    local = robustness_sweep(4, seed=3, short=True, engine=EngineSettings(workers=2), progress=False)
    assert local.engine["kind"] == "dask" and local.engine["workers"] == 2
    assert local.success
    assert_same_runs(local.runs, serial.runs)


def test_killed_worker_loses_no_run(serial):
    seeds = run_seeds(3, 4)
    with dask_client(EngineSettings(workers=2)) as client:
        pids = client.run(os.getpid)
        lost: list = []

        def kill_a_busy_worker():  # as soon as a worker holds a run, kill it (SIGKILL: no clean-up)
            deadline = time.monotonic() + 120
            while time.monotonic() < deadline:
                busy = [(w, keys) for w, keys in client.processing().items() if keys and w in pids]
                if busy:
                    lost.extend(busy[0][1])
                    os.kill(pids[busy[0][0]], signal.SIGKILL)
                    return
                time.sleep(0.05)

        killer = threading.Thread(target=kill_a_busy_worker)
        killer.start()
        outcomes = map_tasks(client, sweep_run, seeds, progress=False, short=True)
        killer.join()
    assert lost, "no worker was killed while holding a run: the test proved nothing"
    assert all(o.success for o in outcomes), [o.message for o in outcomes]
    assert_same_runs([o.value for o in outcomes], serial.runs)


def test_failing_task_is_recorded_not_dropped():
    with dask_client(EngineSettings(workers=1)) as client:
        outcomes = map_tasks(client, draw, [1, -1, 2], progress=False)
    assert [o.item for o in outcomes] == [1, -1, 2]
    assert [o.success for o in outcomes] == [True, False, True]
    assert "ValueError" in outcomes[1].message and outcomes[0].value == draw(1)


def test_cli_sweep_writes_the_contract_json(tmp_path, capsys):
    out = tmp_path / "sweep.json"
    assert main(["sweep", "--runs", "2", "--short", "--seed", "3", "--workers", "1", "--json", str(out),
                 "--plot", str(tmp_path / "sweep.png")]) == 0
    data = json.loads(out.read_text())
    assert set(data["engine"]) == {"kind", "address", "workers"} and data["engine"]["kind"] == "dask"
    assert [r["seed"] for r in data["runs"]] == run_seeds(3, 2)
    for run in data["runs"]:
        assert {"seed", "success", "max_winding_c", "limit_c", "violations", "cutoff_trips",
                "achieved_hold_s"} <= set(run)
    assert {"runs", "violations", "cutoff_trips", "median_hold_ratio"} <= set(data["summary"])
    assert (tmp_path / "sweep.png").stat().st_size > 0


@pytest.mark.parametrize("argv, field", [(["--runs", "0"], "runs"), (["--seed", "-1"], "seed"),
                                          (["--scheduler", "nonsense"], "scheduler"),
                                          (["--scheduler", "tcp://127.0.0.1:9"], "--scheduler")])
def test_cli_sweep_bad_input_is_one_line_exit_2(argv, field, tmp_path, capsys):
    assert main(["sweep", "--short", "--json", str(tmp_path / "s.json"), *argv]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and field in err, err
    assert not (tmp_path / "s.json").exists()


@pytest.fixture(scope="module")
def fleet_csvs(tmp_path_factory):
    """Two robots' recordings: one whose drive heats the motor (concealed from the model), one without."""
    from thermo_ddp.testing.testbed import PlantParameters, static_3a

    folder = tmp_path_factory.mktemp("fleet")
    paths = []
    for name, effects in (("robot_a", "drive"), ("robot_b", "none")):
        rec = static_3a(params=PlantParameters().with_effects(effects), heating_s=1800.0, cooling_s=1800.0)
        paths.append(str(folder / f"{name}.csv"))
        rec.to_csv(paths[-1])
    return paths


def test_fleet_diagnosis_on_the_cluster_equals_one_by_one(fleet_csvs):
    from thermo_ddp.studies.fleet import diagnose_fleet, diagnose_one

    fleet = diagnose_fleet(fleet_csvs, engine=EngineSettings(workers=2), progress=False)
    assert fleet.engine["workers"] == 2 and fleet.recordings == tuple(fleet_csvs)
    for path, d in zip(fleet_csvs, fleet.diagnoses):
        alone = diagnose_one(path)
        assert [t["term"] for t in d["missing_physics"]] == [t["term"] for t in alone["missing_physics"]]
        assert d["final"]["rmse"] == alone["final"]["rmse"]
    assert fleet.terms().get("drive_heating") == [fleet_csvs[0]]   # the drive-heated robot, only
    assert "robot_a.csv" in fleet.report() and fleet.to_dict()["summary"]["terms"] == fleet.terms()


def test_cli_diagnose_each_writes_one_diagnosis_per_recording(fleet_csvs, tmp_path, capsys):
    out = tmp_path / "fleet.json"
    code = main(["diagnose", *fleet_csvs, "--each", "--workers", "1", "--json", str(out)])
    data = json.loads(out.read_text())
    assert code == (0 if data["success"] else 1)
    assert [d["recording"] for d in data["diagnoses"]] == fleet_csvs
    assert data["summary"]["terms"].get("drive_heating") == [fleet_csvs[0]]
    assert "robot_b.csv" in capsys.readouterr().out


def test_cli_diagnose_each_checks_every_recording_before_the_cluster(fleet_csvs, tmp_path, capsys):
    bad = tmp_path / "bad.csv"
    bad.write_text("time_s,current_a,temperature_c\n0,1,30\n1,1,nan\n")
    assert main(["diagnose", *fleet_csvs, str(bad), "--each", "--json", str(tmp_path / "f.json")]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "bad.csv" in err and "row 3" in err
    assert main(["diagnose", *fleet_csvs, "--each", "--plot", str(tmp_path / "f.png")]) == 2
    assert "--each" in capsys.readouterr().err


def test_failed_resolves_are_counted_per_run_and_summarised():
    """A re-solve that failed is counted from each run's events (not printed per period): the summary and
    the report add them up and never say none when there were some."""
    from thermo_ddp.studies.sweep import SweepResult

    def run(seed, excess=0.0, **events):
        return {"seed": seed, "success": True, "violations": 0, "cutoff_trips": 0, "hold_ratio": 1.0,
                "margin_c": 1.0, "fallbacks": sum(events.values()), "events": events,
                "range_violations": int(excess > 0), "max_range_excess_rad": excess, "actuator_violations": 0}
    runs = (run(1), run(2, 0.36, solve_failed=2, fallback_plan=2), run(3, solve_timeout=1, fallback_plan=1))
    result = SweepResult({"kind": "serial", "address": "in-process", "workers": 1}, runs, 0, True, 1.0)
    s = result.summary()
    assert s["failed_resolves"] == 3 and s["runs_with_failed_resolves"] == 2 and s["runs_with_fallback"] == 2
    assert "re-solves that failed or came too late: 3 in 2 run(s)" in result.report()
    assert s["range_violations"] == 1 and s["max_range_excess_rad"] == 0.36 and s["actuator_violations"] == 0
    assert "runs outside the joint range 1 (largest excess 0.360 rad)" in result.report()
