"""Robustness sweep: randomised closed-loop lifts (plant thermal values +-25 %, friction +-30 %, sensor
noise and quantisation, initial temperature 30-60 °C), one Dask task per run (see ``studies.engine``).

A run is a pure function of its seed: :func:`sweep_run` draws the plant and sensors from the seed alone
and builds (or loads from the disk cache) its solver in the worker, so the same seed gives the same
numbers serially, on a LocalCluster or on any cluster. Every run is paired with a nominal run (the
planner's own model as plant, the same initial temperature and controller): the hold achieved is
reported as a fraction of that nominal hold.
"""
from __future__ import annotations

import contextlib
import dataclasses
import functools
import logging
import time
from typing import Any

import numpy as np
from tqdm import tqdm

from .._config import require
from .._figures import new_figure
from .._progress import hidden
from ..model.parameters import THERMAL_KEYS as FILE_THERMAL_KEYS
from ..mpc.closed_loop import build_models, run_closed_loop
from ..mpc.controller import mpc_solver, planning_problem
from ..mpc.observer import ObserverSettings
from ..mpc.settings import MPCSettings
from .engine import EngineSettings, dask_client, engine_info, map_tasks

# [thermal] values drawn independently in +-THERMAL_SPREAD (every numeric one but the room and the
# friction-heat share); the planner keeps the file's values.
THERMAL_KEYS = FILE_THERMAL_KEYS["two_node_drive"]
THERMAL_SPREAD, FRICTION_SPREAD = 0.25, 0.30
INITIAL_C = (30.0, 60.0)
MAX_RUNS = 100_000  # a sweep's runs are kept in memory and written as one JSON

# The controller of the sweep: the casing sensor and the motor voltage (resistance thermometry of the
# winding) in the EKF, a settled start (winding = casing), a larger prior on the resistance scale, a
# winding process noise that lets the voltage correct a wrong heat capacity, and a back-off of 2 sigma;
# the hold robust to the sweep's own thermal spread (mpc.robust), unless the nominal plan is asked for.
CONTROLLER = dict(hold_s=15.0, observe_voltage=True, observer_start="settled", uncertainty_sigmas=2.0,
                  plant_resistance_scale=1.0, robust_uncertainty=THERMAL_SPREAD)
NOMINAL_PLAN = dict(robust_uncertainty=0.0)  # --nominal-plan: the hold of the planner's model alone
SHORT = dict(hold_s=5.0)  # --short: a 5 s hold instead of 15 s
RESOLVE_FAILURES = ("solve_failed", "solve_timeout")  # a run's events that are a failed re-solve
OBSERVER = ObserverSettings(winding_c=0.3, initial_resistance_scale=0.15)


def run_seeds(seed: int, runs: int) -> list[int]:
    """The per-run seeds of a sweep: the first ``runs`` words of the stream of ``seed`` (a longer sweep
    with the same seed repeats a shorter one's runs and adds more)."""
    return [int(s) for s in np.random.SeedSequence(seed).generate_state(runs, dtype=np.uint32)]


def draw(seed: int) -> dict[str, Any]:
    """The randomised plant and sensors of the run with this seed (MPCSettings fields)."""
    rng = np.random.default_rng(seed)
    scales = tuple((k, float(rng.uniform(1 - THERMAL_SPREAD, 1 + THERMAL_SPREAD))) for k in THERMAL_KEYS)
    return {"plant_thermal_scales": scales,
            "plant_friction_scale": float(rng.uniform(1 - FRICTION_SPREAD, 1 + FRICTION_SPREAD)),
            "casing_noise_c": float(rng.uniform(0.05, 0.2)),
            "casing_quantum_c": float(rng.choice([0.0625, 0.1, 0.25])),
            "current_noise_a": float(rng.uniform(0.01, 0.05)),
            "voltage_noise_v": float(rng.uniform(0.02, 0.1)),
            "plant_initial_c": float(rng.uniform(*INITIAL_C)),
            "seed": int(seed)}


def _controller(short: bool, nominal_plan: bool = False) -> dict[str, Any]:
    return {**CONTROLLER, **(SHORT if short else {}), **(NOMINAL_PLAN if nominal_plan else {})}


@functools.cache
def _solver(short: bool):
    """The sweep controller's solver, built once per process (its compiled passes come from the disk cache)."""
    settings = MPCSettings.from_options(**_controller(short))
    model, _ = build_models(settings)
    return mpc_solver(planning_problem(settings, model), settings)


def sweep_run(seed: int, short: bool = False, nominal_plan: bool = False) -> dict[str, Any]:
    """One randomised closed loop and its nominal twin: a pure function of ``seed`` (and ``short``,
    ``nominal_plan``); plain numbers only (the Sweep JSON's run entry)."""
    solver = _solver(short)
    d = draw(seed)
    controller = _controller(short, nominal_plan)
    settings = MPCSettings.from_options(**controller, **d)
    nominal = MPCSettings.from_options(**controller, plant_initial_c=d["plant_initial_c"], seed=int(seed))
    t0 = time.perf_counter()
    with _per_period_lines_off():
        r = run_closed_loop(settings, solver=solver, observer=OBSERVER, progress=False)
        n = run_closed_loop(nominal, solver=solver, observer=OBSERVER, progress=False)
    hold, nominal_hold = float(r.hold_s[-1]), float(n.hold_s[-1])
    excess, actuator = r.range_excess_rad, r.actuator_excess
    return {"seed": int(seed), "success": bool(r.success), "status": r.status, "message": r.message,
            "max_winding_c": float(r.peak_winding_c), "limit_c": float(r.limit_c),
            "violations": int(np.count_nonzero(r.winding_c > r.limit_c)), "cutoff_trips": int(r.cutoff_tripped),
            "range_violations": int(np.count_nonzero(excess > 0)), "max_range_excess_rad": float(excess.max()),
            "actuator_violations": int(np.count_nonzero(np.logical_or(*(e > 0 for e in actuator.values())))),
            "max_current_excess_a": float(actuator["current_a"].max()),
            "max_voltage_excess_v": float(actuator["voltage_v"].max()),
            "achieved_hold_s": hold, "nominal_hold_s": nominal_hold,
            "hold_ratio": hold / nominal_hold if nominal_hold > 0 else None,
            "margin_c": float(r.margin_c), "nominal_margin_c": float(n.margin_c),
            "max_abs_estimation_error_c": float(np.abs(r.estimation_error_c).max()),
            "fallbacks": int(r.step_status.count("fallback")),
            "events": {k: v["count"] for k, v in r.event_counts().items()},
            "draw": {**d, "plant_thermal_scales": dict(d["plant_thermal_scales"])},
            "wall_s": time.perf_counter() - t0}


@contextlib.contextmanager
def _per_period_lines_off():
    """The controller's line per failed re-solve off during a run (the run counts them in its ``events``:
    ``solve_failed``, ``solve_timeout``; the sweep's summary adds them up)."""
    logger = logging.getLogger("thermo_ddp.mpc.controller")
    level = logger.level
    logger.setLevel(logging.ERROR)
    try:
        yield
    finally:
        logger.setLevel(level)


def _failed_resolves(run: dict[str, Any]) -> int:
    return sum(run["events"].get(name, 0) for name in RESOLVE_FAILURES)


@dataclasses.dataclass(frozen=True)
class SweepResult:
    """A sweep's runs in seed order, the engine that ran them, and its summary (the Sweep JSON)."""

    engine: dict[str, Any]
    runs: tuple[dict[str, Any], ...]
    seed: int
    short: bool
    wall_s: float
    nominal_plan: bool = False

    @property
    def success(self) -> bool:
        """Every run ran to the end (a run that breaks the limit is a result, not a failure of the sweep)."""
        return all("error" not in r for r in self.runs)

    @property
    def status(self) -> str:
        return "ok" if self.success else "runs_failed"

    @property
    def message(self) -> str:
        failed = [r["seed"] for r in self.runs if "error" in r]
        return f"{len(self.runs)} runs" + (f"; {len(failed)} failed (seeds {failed})" if failed else "")

    def summary(self) -> dict[str, Any]:
        done = [r for r in self.runs if "error" not in r]
        ratios = [r["hold_ratio"] for r in done if r["hold_ratio"] is not None]
        return {"runs": len(self.runs), "failed_runs": len(self.runs) - len(done),
                "violations": sum(r["violations"] > 0 for r in done),
                "cutoff_trips": sum(r["cutoff_trips"] for r in done),
                "range_violations": sum(r["range_violations"] > 0 for r in done),
                "max_range_excess_rad": max((r["max_range_excess_rad"] for r in done), default=None),
                "actuator_violations": sum(r["actuator_violations"] > 0 for r in done),
                "median_hold_ratio": float(np.median(ratios)) if ratios else None,
                "min_hold_ratio": float(np.min(ratios)) if ratios else None,
                "min_margin_c": min((r["margin_c"] for r in done), default=None),
                "runs_with_fallback": sum(r["fallbacks"] > 0 for r in done),
                "failed_resolves": sum(_failed_resolves(r) for r in done),
                "runs_with_failed_resolves": sum(_failed_resolves(r) > 0 for r in done),
                "wall_s": self.wall_s}

    def to_dict(self) -> dict[str, Any]:
        return {"success": self.success, "status": self.status, "message": self.message,
                "engine": self.engine, "seed": self.seed, "short": self.short, "nominal_plan": self.nominal_plan,
                "controller": {**_controller(self.short, self.nominal_plan), "observer": dataclasses.asdict(OBSERVER)},
                "spreads": {"thermal": THERMAL_SPREAD, "friction": FRICTION_SPREAD, "initial_c": list(INITIAL_C)},
                "runs": list(self.runs), "summary": self.summary()}

    def report(self) -> str:
        s = self.summary()
        ratio = "n/a" if s["median_hold_ratio"] is None else f"{s['median_hold_ratio']:.2f}"
        margin = "n/a" if s["min_margin_c"] is None else f"{s['min_margin_c']:.2f} K"
        excess = "n/a" if s["max_range_excess_rad"] is None else f"{s['max_range_excess_rad']:.3f} rad"
        failed = [r["seed"] for r in self.runs if "error" in r]
        plan = "nominal hold" if self.nominal_plan else f"hold robust to +-{100 * THERMAL_SPREAD:g} %"
        engine = f"{self.engine['kind']} ({self.engine['address']}, {self.engine['workers']} workers)"
        lines = [f"sweep ({plan}) on {engine}: "
                 f"{s['runs']} runs in {self.wall_s:.1f} s, {s['failed_runs']} did not run to the end"
                 + (f" (seeds {', '.join(map(str, failed[:5]))}{' ...' if len(failed) > 5 else ''}; messages in "
                    "the JSON)" if failed else ""),
                 f"  runs over the winding limit {s['violations']}, cut-off trips {s['cutoff_trips']}, "
                 f"minimum margin {margin}",
                 f"  runs outside the joint range {s['range_violations']} (largest excess {excess}), "
                 f"over the current peak or the bus voltage {s['actuator_violations']}",
                 f"  median hold / nominal hold {ratio}",
                 f"  re-solves that failed or came too late: {s['failed_resolves']} in "
                 f"{s['runs_with_failed_resolves']} run(s); runs that used the fallback plan {s['runs_with_fallback']}"]
        return "\n".join(lines)

    def plot(self, path) -> None:
        done = [r for r in self.runs if "error" not in r]
        fig, (a, b) = new_figure(1, 2, (9, 3.5))
        a.hist([r["margin_c"] for r in done], bins=20, color="tab:blue")
        a.set(xlabel="margin under the winding limit [K]", ylabel="runs [count]", title="true winding margin")
        b.hist([100 * r["hold_ratio"] for r in done if r["hold_ratio"] is not None], bins=20, color="tab:green")
        b.set(xlabel="hold achieved / nominal hold [%]", ylabel="runs [count]", title="hold achieved")
        fig.tight_layout()
        fig.savefig(path, dpi=120)


def _failed(seed: int, message: str) -> dict[str, Any]:
    return {"seed": int(seed), "success": False, "status": "error", "message": message, "error": message}


def robustness_sweep(runs: int = 200, seed: int = 0, short: bool = False,
                     engine: EngineSettings | None = EngineSettings(), progress: bool | None = True,
                     nominal_plan: bool = False) -> SweepResult:
    """``runs`` randomised closed loops: on Dask (``engine``: a LocalCluster by default, or the cluster
    at ``engine.scheduler``), or in this process one after the other when ``engine`` is None. The
    controller's hold is robust to the sweep's thermal spread (``nominal_plan``: the model's alone)."""
    integer = isinstance(runs, (int, np.integer)) and not isinstance(runs, bool)
    require(integer and 1 <= runs <= MAX_RUNS, "robustness_sweep", "runs", runs, f"expected an integer in [1, {MAX_RUNS}]")
    require(isinstance(seed, (int, np.integer)) and seed >= 0, "robustness_sweep", "seed", seed,
            "expected an integer >= 0 (a numpy SeedSequence entropy)")
    seeds = run_seeds(seed, int(runs))
    started = time.perf_counter()
    if engine is None:
        results = tuple(sweep_run(s, short, nominal_plan) for s in tqdm(seeds, desc="sweep", disable=hidden(progress)))
        info = {"kind": "serial", "address": "in-process", "workers": 1}
    else:
        with dask_client(engine) as client:
            info = engine_info(client).to_dict()
            outcomes = map_tasks(client, sweep_run, seeds, progress=progress, desc="sweep", short=short,
                                 nominal_plan=nominal_plan)
        results = tuple(o.value if o.success else _failed(o.item, o.message) for o in outcomes)
    return SweepResult(info, results, int(seed), bool(short), time.perf_counter() - started, bool(nominal_plan))
