"""Robustness sweep: randomised closed-loop lifts (plant thermal values +-25 %, friction +-30 %, sensor
noise and quantisation, initial temperature 30-60 °C), in parallel processes.

Every run is paired with a nominal run (the planner's own model as plant, the same initial temperature
and controller): the hold achieved is reported as a fraction of that nominal hold.
"""
from __future__ import annotations

import dataclasses
import functools
import multiprocessing
import time
from concurrent.futures import ProcessPoolExecutor
from typing import Any

import numpy as np
from tqdm import tqdm

from ..mpc.closed_loop import run_closed_loop
from ..mpc.controller import mpc_solver, planning_problem
from ..mpc.closed_loop import build_models
from ..mpc.observer import ObserverSettings
from ..mpc.settings import MPCSettings
from ..model.parameters import THERMAL_KEYS as FILE_THERMAL_KEYS

# [thermal] values drawn independently in +-THERMAL_SPREAD (every numeric one but the room and the
# friction-heat share); the planner keeps the file's values.
THERMAL_KEYS = FILE_THERMAL_KEYS["two_node_drive"]
THERMAL_SPREAD, FRICTION_SPREAD = 0.25, 0.30
INITIAL_C = (30.0, 60.0)

# The controller of the sweep: the casing sensor and the motor voltage (resistance thermometry of the
# winding) in the EKF, a settled start (winding = casing), a larger prior on the resistance scale, a
# winding process noise that lets the voltage correct a wrong heat capacity, and a back-off of 2 sigma.
CONTROLLER = dict(hold_s=15.0, observe_voltage=True, observer_start="settled", uncertainty_sigmas=2.0,
                  plant_resistance_scale=1.0)
OBSERVER = ObserverSettings(winding_c=0.3, initial_resistance_scale=0.15)

def draw(run: int, seed: int = 0) -> dict[str, Any]:
    """The randomised plant and sensors of run ``run`` (MPCSettings fields)."""
    rng = np.random.default_rng((seed, run))
    scales = tuple((k, float(rng.uniform(1 - THERMAL_SPREAD, 1 + THERMAL_SPREAD))) for k in THERMAL_KEYS)
    return {"plant_thermal_scales": scales,
            "plant_friction_scale": float(rng.uniform(1 - FRICTION_SPREAD, 1 + FRICTION_SPREAD)),
            "casing_noise_c": float(rng.uniform(0.05, 0.2)),
            "casing_quantum_c": float(rng.choice([0.0625, 0.1, 0.25])),
            "current_noise_a": float(rng.uniform(0.01, 0.05)),
            "voltage_noise_v": float(rng.uniform(0.02, 0.1)),
            "plant_initial_c": float(rng.uniform(*INITIAL_C)),
            "seed": int(run)}


@functools.cache
def controller_solver():
    """The sweep controller's solver, built once per process (its compiled passes come from the disk cache)."""
    settings = MPCSettings.from_options(**CONTROLLER)
    model, _ = build_models(settings)
    return mpc_solver(planning_problem(settings, model), settings)


def one_run(run: int, seed: int) -> dict[str, Any]:
    """The randomised run and its nominal twin: a pure function of (run, seed); figures only (picklable)."""
    solver = controller_solver()
    d = draw(run, seed)
    settings = MPCSettings.from_options(**CONTROLLER, **d)
    nominal = MPCSettings.from_options(**CONTROLLER, plant_initial_c=d["plant_initial_c"], seed=int(run))
    t0 = time.perf_counter()
    r = run_closed_loop(settings, solver=solver, observer=OBSERVER, progress=False)
    n = run_closed_loop(nominal, solver=solver, observer=OBSERVER, progress=False)
    return {"run": run, "draw": {**d, "plant_thermal_scales": dict(d["plant_thermal_scales"])},
            "status": r.status, "violation": bool(r.peak_winding_c > r.limit_c), "tripped": bool(r.cutoff_tripped),
            "margin_c": float(r.margin_c), "peak_winding_c": float(r.peak_winding_c),
            "hold_s": float(r.hold_s[-1]), "nominal_hold_s": float(n.hold_s[-1]),
            "nominal_margin_c": float(n.margin_c),
            "max_abs_estimation_error_c": float(np.abs(r.estimation_error_c).max()),
            "events": {k: v["count"] for k, v in r.event_counts().items()},
            "fallbacks": int(r.step_status.count("fallback")), "wall_s": time.perf_counter() - t0}


def robustness_sweep(runs: int = 200, workers: int = 2, seed: int = 0, progress: bool = True) -> dict[str, Any]:
    """``runs`` randomised closed loops on ``workers`` processes; the figures and every run."""
    started = time.perf_counter()
    indices = range(runs)
    if workers > 1:
        # spawned workers inherit nothing: each run is rebuilt from its arguments alone
        with ProcessPoolExecutor(workers, mp_context=multiprocessing.get_context("spawn")) as pool:
            results = list(tqdm(pool.map(one_run, indices, [seed] * runs), total=runs, desc="sweep",
                                disable=not progress))
    else:
        results = [one_run(i, seed) for i in tqdm(indices, desc="sweep", disable=not progress)]
    holds = np.array([r["hold_s"] / r["nominal_hold_s"] if r["nominal_hold_s"] > 0 else np.nan for r in results])
    return {"runs": runs, "workers": workers, "seed": seed,
            "violations": int(sum(r["violation"] for r in results)),
            "cutoff_trips": int(sum(r["tripped"] for r in results)),
            "min_margin_c": float(min(r["margin_c"] for r in results)),
            "median_hold_fraction": float(np.nanmedian(holds)) if np.any(np.isfinite(holds)) else None,
            "min_hold_fraction": float(np.nanmin(holds)) if np.any(np.isfinite(holds)) else None,
            "runs_with_fallback": int(sum(r["fallbacks"] > 0 for r in results)),
            "wall_s": time.perf_counter() - started,
            "controller": {**CONTROLLER, "observer": dataclasses.asdict(OBSERVER)},
            "spreads": {"thermal": THERMAL_SPREAD, "friction": FRICTION_SPREAD, "initial_c": INITIAL_C},
            "results": results}
