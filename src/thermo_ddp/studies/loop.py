"""Close the loop: robot recordings -> identification -> diagnosis -> improved model -> plan ->
receding-horizon execution on the robot, for the report's ORIGINAL model and the IMPROVED one.

The "robot" is the testbed's simulated elbow (``thermo_ddp.testing.testbed``) with its concealed physics on:
friction heating and drive heat. It "records" the seed report's three experiments (section 4.3) and a
winding pulse test, with its motor voltage logged; the tool identifies the report's one-node model
(the ORIGINAL: eq. 7 with R(T), constant ambient, no friction heat), diagnoses the misfit, fits the
diagnosed structure again on every sample with the voltage as a winding thermometer and writes that
as the IMPROVED parameter file. Both are then used to
plan the 40 kg lift under 84 °C and 140 °C (:func:`thermo_ddp.tasks.lift.plan_lift`) and to run it in
closed loop (EKF + receding-horizon DDP of :mod:`thermo_ddp.mpc`) on a plant that carries the
robot's TRUE physics (:func:`truth_model`).

Truth mapping (testbed ``PlantParameters`` -> the plant's ``JointParameters`` and network):

- motor: gear ratio, torque constant, rotor inertia, R(T) (resistance, reference, copper alpha),
  viscous and Coulomb friction and the tanh smoothing are the testbed's; back-EMF (K_b = K_m),
  bus voltage and current ratings, which the testbed does not model, come from the elbow file;
- thermal: the testbed's winding/casing/drive capacities, resistances, drive idle and i^2 losses,
  ambient = the testbed room; the friction heat is split as in the testbed (``friction_to_winding``
  into the winding, the rest into the casing): the plant gets its own network with two friction
  sources, while the contract file (``friction_heating_fraction``) can only send it to the casing;
- not carried over: the testbed's 0.2 N·m effort offset and its pendulum forearm (mass, COM,
  inertia): the closed-loop plant's rigid body is the Talos URDF forearm with the payload at the
  gripper, the same as the planner's, so the closed loop compares thermal models only.

The original model's sensor node is its winding (the report assumed the sensor reads the winding);
the EKF measures each model's own sensor node, and the improved model's also the motor voltage.
"""
from __future__ import annotations

import dataclasses
import json
import logging
import math
import tempfile
from pathlib import Path
from typing import Any

import numpy as np
from tqdm import tqdm

from .._config import require, settings_from_mapping
from ..errors import InputError, RunFailed
from ..model.actuated import ActuatedArm, load_model
from ..model.arm import ELBOW, PAYLOAD_KG, ArmSettings
from ..diagnose.figure import plot_thermal_diagnosis
from ..diagnose.thermal import ThermalDiagnosis, ThermalDiagnosisSettings, diagnose_thermal
from ..identify.thermal import ThermalFit, identify_thermal, parameter_file
from ..tasks.experiment import MAX_DURATION_S, ExperimentSettings, write_programme
from ..tasks.limits import (HOLD_S, MAX_LIMITS, check_fields, check_idle_below_limits, check_limit_c, default_limit_c,
                            joint_limit_c)
from ..tasks.lift import LiftPlan, LiftSettings, plan_lift
from ..mpc import ClosedLoopResult, MPCSettings, run_closed_loop
from ..model.parameters import (JointParameters, load_parameters, packaged_parameter_file, parameters_from_dict,
                                save_parameters)
from ..testing.testbed import (COLUMNS, LOGGED_COLUMNS, Ambient, PlantParameters, SimulatedRecording, biceps, static_3a,
                      static_4a, winding_pulses)
from ..model.thermal import HeatSource, ThermalNetwork, network_from_parameters
from .._progress import hidden
from .experiment_loop import ExperimentStage, experiment_stage
from ..outputs import check_output_folder, write_folder_atomically
from ..recordings import ColumnMap, load_column_map, read_recordings

log = logging.getLogger(__name__)
_SRC = "loop"
MODELS = ("original", "improved")
ORACLE = "truth"  # the robot's own parameter file as the planner's model: what perfect knowledge achieves
# LoopSettings.short(): 30-minute experiments (and designed experiment), a 45 s hold (still longer than the robot can hold 40 kg under
# 140 °C) and no oracle
SHORT_DEFAULTS = {"hold_s": 45.0, "heating_s": 1800.0, "cooling_s": 1800.0, "oracle": False, "experiment_s": 1800.0}


# ----------------------------------------------------------------------------- settings
@dataclasses.dataclass(frozen=True)
class LoopSettings:
    """The whole chain. Experiments: the report's durations (heating ``heating_s``, the biceps curl half
    of it, cooling ``cooling_s``); the lift: ``payload_kg`` at the gripper, hold ``hold_s`` requested of
    the planner and of the closed loop, each winding limit of ``limits_c``; the closed loop: the
    planner backs off ``backoff_c`` from the limit, ``horizon_knots`` knots of 0.1 s (None: the whole
    task, lift + hold + lower + settle; a shorter window cannot plan a hold that outlasts it, its
    terminal return constraint contradicts the hold band), sensor ``seed``. ``oracle``: also plan and
    execute with the robot's true parameter file (the best any identified model can do).

    ``experiment_s``: when the diagnosis leaves items undetermined, the experiment designed to settle them
    (:func:`~thermo_ddp.tasks.experiment.design_experiment`, at most this long, under the lowest of
    ``limits_c`` and the elbow file's cut-off) runs on the robot and the diagnosis is repeated with its log
    (:func:`~thermo_ddp.studies.experiment_loop.experiment_stage`); None: no experiment stage.

    ``pulse_test``: also record :func:`~thermo_ddp.testing.testbed.winding_pulses` (not in the report), which
    excites the winding's time constant. ``voltage``: the robot logs its motor voltage; the
    identification uses it as a winding thermometer and the improved model's observer measures it.
    The original model (the diagnosis' one-node baseline, fitted to the same recordings; one node has no
    winding apart from its sensor, so the voltage does not inform it) runs on the casing sensor alone,
    as the report did."""

    payload_kg: float = 40.0
    limits_c: tuple[float, ...] = (84.0, 140.0)
    hold_s: float = 60.0
    heating_s: float = 7200.0
    cooling_s: float = 5400.0
    backoff_c: float = 1.0
    horizon_knots: int | None = None
    seed: int = 0
    oracle: bool = True
    pulse_test: bool = True
    voltage: bool = True
    experiment_s: float | None = 3600.0
    progress: bool | None = None

    def __post_init__(self):
        require(0 < len(self.limits_c) <= MAX_LIMITS, _SRC, "limits_c", self.limits_c,
                f"give 1 to {MAX_LIMITS} winding limits (each is a plan and a closed loop per model)")
        elbow = load_parameters(packaged_parameter_file(ELBOW))  # every limit checked before the experiments
        object.__setattr__(self, "limits_c", tuple(joint_limit_c(elbow, check_limit_c(_SRC, v)) for v in self.limits_c))
        check_fields(self, _SRC, {"payload_kg": PAYLOAD_KG, "hold_s": HOLD_S})
        for name in ("payload_kg", "hold_s", "heating_s", "cooling_s"):
            value = getattr(self, name)
            require(isinstance(value, (int, float)) and math.isfinite(value) and value > 0, _SRC, name, value,
                    "expected a finite number > 0")
        require(self.experiment_s is None or (isinstance(self.experiment_s, (int, float))
                                              and 0 < self.experiment_s <= MAX_DURATION_S), _SRC, "experiment_s",
                self.experiment_s, f"must be in (0, {MAX_DURATION_S:g}] s, or None for no experiment")
        require(self.heating_s >= 600 and self.cooling_s >= 600, _SRC, "heating_s/cooling_s",
                (self.heating_s, self.cooling_s), "experiments need >= 600 s of heating and of cooling")

    @classmethod
    def short(cls, **options) -> "LoopSettings":
        """:data:`SHORT_DEFAULTS` (overridden by ``options``), for tests and the notebook's quick run."""
        return settings_from_mapping(cls, SHORT_DEFAULTS | options, _SRC)

    @property
    def models(self) -> tuple[str, ...]:
        return MODELS + ((ORACLE,) if self.oracle else ())


# ----------------------------------------------------------------------------- the robot
def robot_parameters() -> PlantParameters:
    """The simulated robot elbow: testbed defaults with friction heating and drive heat."""
    return PlantParameters().with_effects("both")


def record_experiments(robot: PlantParameters, settings: LoopSettings) -> tuple[SimulatedRecording, ...]:
    """The report's experiments (section 4.3) on the robot: static ~3 A, static ~4 A warm with a bump,
    biceps curl; with ``settings.pulse_test`` also the winding pulse test."""
    h, c = settings.heating_s, settings.cooling_s
    report = (static_3a(params=robot, heating_s=h, cooling_s=c, loading_s=min(600.0, h / 6), seed=settings.seed),
              static_4a(params=robot, heating_s=h, cooling_s=c, seed=settings.seed),
              biceps(params=robot, heating_s=h / 2, cooling_s=c, seed=settings.seed))
    return report + ((winding_pulses(params=robot, seed=settings.seed),) if settings.pulse_test else ())


def truth_parameters(robot: PlantParameters, base: JointParameters | None = None,
                     ambient: Ambient | None = None) -> JointParameters:
    """The robot's true parameters as a parameter file (see the module docstring for the mapping).
    ``friction_heating_fraction`` is the TOTAL share of friction heat in the motor (1 or 0); the
    split between winding and casing is in :func:`truth_network`."""
    base = base or load_parameters(packaged_parameter_file(ELBOW))
    r = robot
    motor = {k: getattr(r, k) for k in ("gear_ratio", "torque_constant_nm_per_a", "resistance_ohm",
                                       "resistance_ref_c", "copper_alpha_per_k", "rotor_inertia_kg_m2",
                                       "viscous_friction_nm_s_per_rad", "coulomb_friction_nm",
                                       "coulomb_smoothing_rad_s")}
    motor["back_emf_v_s_per_rad"] = r.torque_constant_nm_per_a
    keys = ("winding_capacity_j_per_k", "casing_capacity_j_per_k", "winding_casing_k_per_w", "casing_ambient_k_per_w")
    if r.drive_heating:
        keys += ("drive_capacity_j_per_k", "drive_casing_k_per_w", "drive_ambient_k_per_w", "drive_idle_w",
                 "drive_loss_w_per_a2")
    thermal = {"model": "two_node_drive" if r.drive_heating else "two_node",
               "ambient_c": (ambient or Ambient()).room_c, **{k: getattr(r, k) for k in keys},
               "friction_heating_fraction": 1.0 if r.friction_heating else 0.0}
    data = base.to_dict()
    data["motor"].update(motor)
    data["thermal"] = thermal
    data["sources"] = {"truth": "thermo_ddp.testing.testbed PlantParameters of the simulated robot (hidden from the tool); "
                                f"friction heat split {r.friction_to_winding:g} winding / "
                                f"{1 - r.friction_to_winding:g} casing"}
    return parameters_from_dict(data, "testbed truth")


def truth_network(robot: PlantParameters, params: JointParameters) -> ThermalNetwork:
    """The robot's thermal network: the contract's, but the friction heat split between the winding
    (``friction_to_winding``) and the casing, as in the testbed."""
    net = network_from_parameters(params.thermal)
    fric = float(robot.friction_heating)
    split = (HeatSource("winding", "friction_w", fric * robot.friction_to_winding),
             HeatSource("casing", "friction_w", fric * (1 - robot.friction_to_winding)))
    return dataclasses.replace(net, sources=tuple(x for x in net.sources if x.name != "friction_w") + split)


def truth_model(robot: PlantParameters, payload_kg: float, base: JointParameters | None = None) -> ActuatedArm:
    """The closed loop's plant: the Talos elbow with ``payload_kg`` at the gripper and the robot's true
    motor and thermal network (friction heat split as in the testbed).

    """
    params = truth_parameters(robot, base)
    return ActuatedArm.from_parameters(ArmSettings(joints=(ELBOW,), payload_kg=payload_kg), {ELBOW: params},
                                       {ELBOW: truth_network(robot, params)})


# ----------------------------------------------------------------------------- closed loop
def mpc_settings(settings: LoopSettings, limit_c: float, model_file: Path, model: str = "improved") -> MPCSettings:
    """The closed loop's settings (the project's MPC defaults otherwise: 0.1 s period, RK4, sensors);
    the observer measures the motor voltage when ``settings.voltage``, except for the original model."""
    lift = LiftSettings()
    task_s = lift.lift_s + settings.hold_s + lift.lower_s + lift.settle_s
    knots = settings.horizon_knots or int(math.ceil(task_s / MPCSettings().controller.control_period_s - 1e-9))
    return MPCSettings.from_options(payload_kg=settings.payload_kg, limit_c=limit_c, hold_s=settings.hold_s,
                                    backoff_c=settings.backoff_c, horizon_knots=knots, seed=settings.seed,
                                    parameter_file=str(model_file),
                                    observe_voltage=settings.voltage and model != "original")


def execute(model_file: Path, plant_model: ActuatedArm, settings: MPCSettings,
            progress: bool = False) -> ClosedLoopResult:
    """Receding-horizon lift with the planner's model from ``model_file`` (``settings.parameter_file``) on
    ``plant_model``, the robot's true physics."""
    settings = settings.replace(parameter_file=str(model_file))
    return run_closed_loop(settings, plant_model=plant_model, progress=progress)


# ----------------------------------------------------------------------------- the chain
@dataclasses.dataclass(frozen=True)
class Execution:
    """One model under one limit: the open-loop plan and the closed-loop run on the robot."""

    model: str
    limit_c: float
    plan: LiftPlan
    run: ClosedLoopResult

    def row(self) -> dict[str, Any]:
        r, p = self.run, self.plan
        warm = r.warm_solve_s()
        return {"model": self.model, "limit_c": self.limit_c, "thermal_model": p.model.params[ELBOW].thermal.model,
                "requested_hold_s": p.settings.hold_s, "planned_hold_s": p.achieved_hold_s,
                "plan_status": p.status, "plan_peak_winding_c": float(p.series("winding_c").max()),
                "plan_solve_s": float(p.solver["total_solve_s"]),
                "closed_loop_hold_s": r.achieved_hold_s, "closed_loop_status": r.status,
                "peak_true_winding_c": r.peak_winding_c, "margin_c": r.margin_c,
                "time_over_limit_s": r.time_over_limit_s,
                "peak_estimated_winding_c": float(r.estimated_winding_c.max()),
                "peak_measured_casing_c": float(r.measured_casing_c.max()),
                "cutoff_trips": int(r.cutoff_tripped),
                "warm_solve_median_ms": 1e3 * float(np.median(warm)) if warm.size else None,
                "period_solve_max_ms": 1e3 * float(r.solve_s.max()),
                "fallback_periods": r.step_status.count("fallback")}


@dataclasses.dataclass(frozen=True)
class LoopResult:
    """The chain's outcome: recordings, diagnosis, the improved model's fit, the parameter files, every
    execution."""

    settings: LoopSettings
    robot: PlantParameters
    recordings: tuple[SimulatedRecording, ...]
    recording_files: tuple[Path, ...]
    diagnosis: ThermalDiagnosis
    improved_fit: ThermalFit
    model_files: dict[str, Path]
    executions: tuple[Execution, ...]
    experiment: ExperimentStage | None = None   # None: the stage was off

    @property
    def success(self) -> bool:
        return self.diagnosis.success and all(e.run.success for e in self.executions if e.model == "improved")

    @property
    def status(self) -> str:
        return "ok" if self.success else "improved_model_failed"

    @property
    def message(self) -> str:
        return "; ".join(c["statement"] for c in self.claims())

    def execution(self, model: str, limit_c: float) -> Execution:
        return next(e for e in self.executions if e.model == model and e.limit_c == float(limit_c))

    def rows(self) -> list[dict[str, Any]]:
        return [e.row() for e in self.executions]

    def claims(self) -> list[dict[str, Any]]:
        """Per limit, what the improved model buys over the original, in numbers (see :func:`claim`)."""
        out = []
        for lim in self.settings.limits_c:
            c = claim(lim, *(self.execution(m, lim).row() for m in MODELS))
            if self.settings.oracle:
                extra = oracle_claim(self.execution("improved", lim).row(), self.execution(ORACLE, lim).row())
                c |= {k: v for k, v in extra.items() if k != "statement"}
                c["statement"] += extra["statement"]
            out.append(c)
        return out

    def to_dict(self) -> dict[str, Any]:
        d = self.diagnosis.to_dict()
        return {"success": self.success, "status": self.status, "message": self.message,
                "settings": dataclasses.asdict(self.settings),
                "recordings": [str(p) for p in self.recording_files],
                "diagnosis": {"missing_physics": [m["term"] for m in d["missing_physics"]],
                              "baseline_model": d["baseline"]["model"], "final_model": d["final"]["model"],
                              "rmse_before": d["validation"]["rmse_before"],
                              "rmse_after": d["validation"]["rmse_after"]},
                "improved_fit": {"model": self.improved_fit.model, "parameters": dict(self.improved_fit.parameters),
                                 "stderr": dict(self.improved_fit.stderr), "notes": list(self.improved_fit.notes)},
                "identified_vs_true": self.identified_vs_true(),
                "model_files": {k: str(v) for k, v in self.model_files.items()},
                "experiment": None if self.experiment is None else self.experiment.to_dict(),
                "rows": self.rows(), "claims": self.claims()}

    def identified_vs_true(self) -> dict[str, dict[str, float | None]]:
        """The improved model's thermal parameters next to the robot's hidden values (the testbed knows them)."""
        truth = truth_parameters(self.robot).thermal.values
        fit = self.improved_fit
        return {k: {"identified": v, "stderr": fit.stderr.get(k), "true": truth.get(k)}
                for k, v in fit.parameters.items() if k in truth}

    def table(self) -> str:
        head = (f"{self.settings.payload_kg:g} kg lift, requested hold {self.settings.hold_s:g} s; closed loop "
                f"on the robot's true physics\n{'model':>9} {'limit':>6} {'planned s':>10} {'executed s':>11} "
                f"{'peak true':>10} {'margin K':>9} {'over s':>7} {'est. peak':>10} {'trips':>6} "
                f"{'plan s':>7} {'warm ms':>8} {'max ms':>7}")
        lines = [f"{r['model']:>9} {r['limit_c']:6.0f} {r['planned_hold_s']:10.1f} {r['closed_loop_hold_s']:11.1f} "
                 f"{r['peak_true_winding_c']:10.1f} {r['margin_c']:9.2f} {r['time_over_limit_s']:7.1f} "
                 f"{r['peak_estimated_winding_c']:10.1f} {r['cutoff_trips']:6d} {r['plan_solve_s']:7.2f} "
                 f"{r['warm_solve_median_ms'] or float('nan'):8.2f} {r['period_solve_max_ms']:7.1f}"
                 for r in self.rows()]
        return "\n".join([head, *lines])

    def report(self) -> str:
        d = self.to_dict()["diagnosis"]
        stage = self.experiment.report_lines() if self.experiment is not None else []
        return "\n".join([f"close the loop: {self.status}", *stage,
                          f"diagnosis: {d['baseline_model']} -> {d['final_model']}, missing physics "
                          f"{', '.join(d['missing_physics']) or 'none'}, held-out rmse {d['rmse_before']:.3f} -> "
                          f"{d['rmse_after']:.3f} K", self.parameter_table(), self.table(),
                          *(c["statement"] for c in self.claims()), *self.fallback_lines()])

    def fallback_lines(self) -> list[str]:
        """Periods whose re-solve failed or came late (the previous plan's control was applied), per run."""
        counts = {f"{r['model']} {r['limit_c']:g} °C": r["fallback_periods"] for r in self.rows() if r["fallback_periods"]}
        if not counts:
            return []
        return ["re-solves that failed or came late (the previous plan's control applied): "
                + ", ".join(f"{k}: {n}" for k, n in counts.items())]

    def parameter_table(self) -> str:
        """The improved model's thermal parameters (± standard error) next to the robot's hidden values."""
        rows = [f"  {k:28s} {v['identified']:10.4g} ± {v['stderr'] or 0:<8.2g} true {v['true']:.4g}"
                for k, v in self.identified_vs_true().items()]
        return "\n".join([f"improved model, re-identified at full rate ({self.improved_fit.model}) vs the robot's "
                          "hidden values:", *rows])

    def plot(self, path: str | Path) -> Path:
        """Per limit: true and estimated winding, current, measured casing, for both models."""
        from .loop_figures import plot_loop
        return plot_loop(self, Path(path))

    def plot_summary(self, path: str | Path) -> Path:
        """Bars: planned and executed hold, margin to the limit, per model and limit."""
        from .loop_figures import plot_summary
        return plot_summary(self, Path(path))


def claim(limit_c: float, original: dict[str, Any], improved: dict[str, Any]) -> dict[str, Any]:
    """The comparison of two table rows under one limit: does the original break the limit, does the
    improved hold it, and otherwise how much margin and hold the original wastes."""
    o, i = original, improved
    violates = o["margin_c"] < 0
    out = {"limit_c": limit_c, "original_violates": violates,
           "improved_holds": i["margin_c"] >= 0 and not i["cutoff_trips"],
           "original_margin_c": o["margin_c"], "improved_margin_c": i["margin_c"],
           "original_hold_s": o["closed_loop_hold_s"], "improved_hold_s": i["closed_loop_hold_s"],
           "wasted_margin_c": None if violates else o["margin_c"] - i["margin_c"],
           "hold_gain_s": i["closed_loop_hold_s"] - o["closed_loop_hold_s"]}
    improved_text = f"the improved model holds {i['closed_loop_hold_s']:.1f} s with {i['margin_c']:.2f} K margin"
    if violates:
        out["statement"] = (f"{limit_c:g} °C: the original model's closed loop breaks the limit (true winding "
                            f"{o['peak_true_winding_c']:.1f} °C, {-o['margin_c']:.1f} K over, for "
                            f"{o['time_over_limit_s']:.1f} s; its estimate peaked at "
                            f"{o['peak_estimated_winding_c']:.1f} °C); {improved_text}")
    else:
        out["statement"] = (f"{limit_c:g} °C: the original model is conservative: it holds "
                            f"{o['closed_loop_hold_s']:.1f} s with {o['margin_c']:.1f} K margin; {improved_text} "
                            f"(the original wastes {out['wasted_margin_c']:.1f} K of margin and "
                            f"{out['hold_gain_s']:.1f} s of hold)")
    if not out["improved_holds"]:
        out["statement"] += "; the improved model FAILED to hold the limit"
    return out


def oracle_claim(improved: dict[str, Any], truth: dict[str, Any]) -> dict[str, Any]:
    """How far the improved model is from the planner that knows the robot's true parameters
    (``statement``: a clause to append to :func:`claim`'s)."""
    share = improved["closed_loop_hold_s"] / truth["closed_loop_hold_s"] if truth["closed_loop_hold_s"] > 0 else None
    text = (f"; with the TRUE parameters the closed loop holds {truth['closed_loop_hold_s']:.1f} s with "
            f"{truth['margin_c']:.2f} K margin")
    if share is not None:
        text += f" (the improved model gets {100 * share:.0f} % of that hold)"
    return {"oracle_hold_s": truth["closed_loop_hold_s"], "oracle_margin_c": truth["margin_c"],
            "improved_hold_share_of_oracle": share, "statement": text}


def identify_models(recording_files, out_dir: Path, settings: LoopSettings,
                    diagnosis: ThermalDiagnosis | None = None) -> tuple[ThermalDiagnosis, ThermalFit, dict[str, Path]]:
    """Diagnose the recordings (contract CSV files, or recordings read through a column map); re-identify
    the diagnosed structure on every sample (:func:`refit`); write the ORIGINAL (identified one-node baseline,
    constant ambient, no friction heat) and IMPROVED (the re-identified diagnosed structure) parameter files
    into ``out_dir``. ``diagnosis``: the recordings' diagnosis when already computed."""
    diagnosis = diagnosis or diagnose_thermal(list(recording_files),
                                              settings=ThermalDiagnosisSettings(progress=settings.progress))
    if not diagnosis.success:
        raise RunFailed("the loop's diagnosis", diagnosis.status, diagnosis.message)
    improved = refit(diagnosis, recording_files)
    out_dir.mkdir(parents=True, exist_ok=True)
    original = parameter_file(diagnosis.params, diagnosis.baseline_fit, diagnosis.recordings)
    require(original["thermal"]["model"] == "one_node", _SRC, "baseline", original["thermal"]["model"],
            "expected the report's one-node baseline")
    files = {"original": out_dir / f"{ELBOW}_original.toml", "improved": out_dir / f"{ELBOW}_improved.toml"}
    for name, data in (("original", original), ("improved", parameter_file(diagnosis.params, improved, improved.recordings))):
        save_parameters(parameters_from_dict(data, name), files[name])
    return diagnosis, improved, files


def refit(diagnosis: ThermalDiagnosis, recording_files) -> ThermalFit:
    """The diagnosed structure fitted again on every sample, from the diagnosis' values. The diagnosis
    compares its candidates on a 10 s grid (many cross-validation fits); the winding's ~36 s time
    constant and the voltage thermometry (one reading per sample) want the recordings' full rate."""
    final = diagnosis.final_fit
    fit = identify_thermal(list(recording_files), terms=final.terms, parameters=diagnosis.params,
                           start=final.parameters)
    if not fit.success:
        raise RunFailed("the loop's refit", fit.status, fit.message)
    log.info("refit at full rate (%s): %s", fit.model, ", ".join(f"{k} {v:.4g}" for k, v in fit.parameters.items()))
    return fit


def logged_columns(settings: LoopSettings) -> tuple[str, ...]:
    """The robot's logged columns: the report's, and the motor voltage with ``settings.voltage``."""
    return LOGGED_COLUMNS if settings.voltage else COLUMNS


def loop_column_map(columns: ColumnMap | str | Path | None, settings: LoopSettings) -> ColumnMap | None:
    """The column map the robot logs by (``--columns``), checked before any work: writable from the robot's
    columns (:meth:`~thermo_ddp.recordings.ColumnMap.check_writable`) and holding what the diagnosis reads."""
    cmap = load_column_map(columns) if isinstance(columns, (str, Path)) else columns
    if cmap is None:
        return None
    cmap.check_writable(logged_columns(settings))
    for needed in ("current_a", "temperature_c"):
        if needed not in cmap.columns:
            raise InputError(cmap.source, f"columns.{needed}", "missing", "the loop's diagnosis reads it: map it")
    return cmap


def run_loop(settings: LoopSettings | None = None, out_dir: str | Path | None = None,
             columns: ColumnMap | str | Path | None = None, **options) -> LoopResult:
    """The whole chain (see the module docstring); recordings and parameter files go into ``out_dir``
    (a temporary directory when None). ``columns``: a column map (or its TOML file): the robot logs its
    recordings in that map's own column names, and the chain reads them through it, as it would a real
    robot's logs. Options: the fields of :class:`LoopSettings`."""
    if settings is None:
        settings = settings_from_mapping(LoopSettings, options, _SRC)
    elif options:
        raise TypeError("give either settings or options, not both")
    if out_dir is None:
        out_dir = Path(tempfile.mkdtemp(prefix="thermo-ddp-loop-"))
    out_dir = Path(out_dir)
    cmap = loop_column_map(columns, settings)
    elbow = load_model((ELBOW,))  # a limit the resting winding already exceeds is refused before the experiments
    for lim in settings.limits_c:
        check_idle_below_limits(elbow, {ELBOW: lim})
    (out_dir / "recordings").mkdir(parents=True, exist_ok=True)
    robot = robot_parameters()
    cases = [(m, lim) for m in settings.models for lim in settings.limits_c]
    stages = 3 + (settings.experiment_s is not None) + len(cases)
    with tqdm(total=stages, desc="loop", unit="step", disable=hidden(settings.progress)) as bar:
        _stage(bar, "recording the experiments on the simulated robot")
        recordings = record_experiments(robot, settings)
        files = tuple(_log(r, out_dir / "recordings" / f"{r.name}.csv", logged_columns(settings), cmap)
                      for r in recordings)
        sources = list(files if cmap is None else read_recordings(files, cmap).recordings)
        _stage(bar, "diagnosing", done=True)
        diagnosis = diagnose_thermal(sources, settings=ThermalDiagnosisSettings(progress=settings.progress))
        stage = None
        if settings.experiment_s is not None and diagnosis.success:
            _stage(bar, "designing the experiment, running it on the robot, diagnosing again", done=True)
            stage, sources = _experiment(robot, sources, diagnosis, settings, out_dir, cmap)
            diagnosis, recordings = stage.after, recordings + ((stage.run,) if stage.run else ())
            files += (out_dir / "recordings" / f"{stage.run.name}.csv",) if stage.run else ()
        _stage(bar, "re-identifying", done=True)
        diagnosis, improved_fit, model_files = identify_models(sources, out_dir / "models", settings, diagnosis)
        save_parameters(truth_parameters(robot), out_dir / "models" / f"{ELBOW}_truth.toml")
        if settings.oracle:
            model_files[ORACLE] = out_dir / "models" / f"{ELBOW}_truth.toml"
        plant_model = truth_model(robot, settings.payload_kg)
        executions = []
        for model, lim in cases:
            _stage(bar, f"plan and closed loop: {model} model, {lim:g} °C", done=True)
            executions.append(_plan_and_execute(settings, plant_model, model_files[model], model, lim))
        bar.update()
    return LoopResult(settings, robot, recordings, files, diagnosis, improved_fit, model_files, tuple(executions),
                      stage)


def _experiment(robot, sources, diagnosis, settings: LoopSettings, out_dir: Path, cmap):
    """The experiment stage (:func:`~thermo_ddp.studies.experiment_loop.experiment_stage`) under the lowest limit,
    never above the elbow file's cut-off (an identification run is not a lift: it must not trip the robot's
    cut-off); the robot logs the run into recordings/ as it logged the report's experiments."""
    def log_run(run):
        path = _log(run, out_dir / "recordings" / f"{run.name}.csv", logged_columns(settings), cmap)
        return path if cmap is None else read_recordings([path], cmap).recordings[0]
    cutoff = default_limit_c(load_parameters(packaged_parameter_file(ELBOW)))
    design = ExperimentSettings(duration_s=settings.experiment_s, limit_c=min(*settings.limits_c, cutoff),
                                progress=settings.progress)
    return experiment_stage(robot, sources, diagnosis, design, log_run, seed=settings.seed)


def _stage(bar, what: str, done: bool = False) -> None:
    """The loop's progress: the stage that starts now (``done``: the previous one ended), a line with -v."""
    if done:
        bar.update()
    bar.set_postfix_str(what)
    log.info("loop: %s", what)


def _plan_and_execute(settings: LoopSettings, plant_model: ActuatedArm, model_file: Path, model: str,
                      lim: float) -> Execution:
    """One model under one limit: the open-loop plan and its closed loop on the robot's true physics."""
    plan = plan_lift(settings.payload_kg, lim, settings.hold_s, parameter_file=str(model_file))
    run = execute(model_file, plant_model, mpc_settings(settings, lim, model_file, model))
    log.info("%s %g °C: planned %.1f s, executed %.1f s, margin %.2f K", model, lim, plan.achieved_hold_s,
             run.achieved_hold_s, run.margin_c)
    return Execution(model=model, limit_c=lim, plan=plan, run=run)


def _log(recording: SimulatedRecording, path: Path, logged: tuple[str, ...], cmap: ColumnMap | None) -> Path:
    """The robot's log of ``recording``: the contract CSV, or the CSV ``cmap`` reads."""
    if cmap is None:
        return recording.to_csv(path, logged)
    return cmap.write_csv(path, recording.columns)


def loop_files(out_dir: str | Path, *, short: bool = False, columns: str | Path | None = None,
               **options) -> dict[str, Any]:
    """CLI entry (``thermo-ddp loop``): run the chain, write into ``out_dir`` the recordings
    (recordings/*.csv), the parameter files (models/*.toml: original, improved and the hidden truth), the
    designed experiment (experiment.json; experiment.csv and experiment.png when one was designed),
    the diagnosis (diagnosis.json, diagnosis.png), the figures (loop.png, loop_summary.png), the table (loop.json)
    and the report (loop.txt); return the table.

    ``out_dir`` is checked before any work (new, empty, or an earlier run's folder: see
    :func:`thermo_ddp.outputs.check_output_folder`); the run is built in a fresh folder beside it that
    replaces it only when complete, so a failed run leaves an earlier one as it was."""
    settings = LoopSettings.short(**options) if short else settings_from_mapping(LoopSettings, options, _SRC)
    cmap = loop_column_map(columns, settings)
    out_dir = check_output_folder("--out", out_dir)
    if columns is not None and out_dir.resolve() in Path(columns).resolve().parents:
        raise InputError("--columns", "--columns", str(columns), f"inside the output folder {out_dir}, which the "
                         "run replaces: keep the map elsewhere")
    return write_folder_atomically(out_dir, lambda folder: _write_loop(settings, folder, out_dir, cmap))


def _write_loop(settings: LoopSettings, folder: Path, final: Path, cmap: ColumnMap | None) -> dict[str, Any]:
    """The run's files into ``folder``; paths in the table name ``final``, where the folder will be."""
    result = run_loop(settings, folder, cmap)
    (folder / "diagnosis.json").write_text(json.dumps(result.diagnosis.to_dict(), indent=1))
    plot_thermal_diagnosis(result.diagnosis, folder / "diagnosis.png")
    result.plot(folder / "loop.png")
    result.plot_summary(folder / "loop_summary.png")
    if result.experiment is not None:
        (folder / "experiment.json").write_text(json.dumps(result.experiment.design.to_dict(), indent=1))
        if result.experiment.design.designed:
            write_programme(result.experiment.design.programme(), folder / "experiment.csv")
            result.experiment.design.plot(folder / "experiment.png")
    table = result.to_dict()
    def moved(path: str) -> str:
        return str(final / Path(path).relative_to(folder))
    table["recordings"] = [moved(p) for p in table["recordings"]]
    table["model_files"] = {k: moved(p) for k, p in table["model_files"].items()}
    (folder / "loop.json").write_text(json.dumps(table, indent=1))
    (folder / "loop.txt").write_text(result.report() + "\n")
    return table


__all__ = ["Execution", "LoopResult", "LoopSettings", "claim", "execute", "identify_models", "logged_columns",
           "loop_column_map", "loop_files", "record_experiments", "refit", "robot_parameters", "run_loop", "truth_model",
           "truth_network", "truth_parameters"]
