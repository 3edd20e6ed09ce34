"""Receding-horizon control of the elbow lift (plant, observer, controller; do-mpc style separation)."""
from .closed_loop import ClosedLoopResult, build_models, run_closed_loop
from .controller import ControlStep, RecedingHorizonController, mpc_solver, planning_problem
from .observer import ExtendedKalmanFilter, ObserverSettings, scaled_ode
from .plant import Measurement, Plant, perturbed_model
from .settings import MPCSettings

__all__ = ["ClosedLoopResult", "ControlStep", "ExtendedKalmanFilter", "MPCSettings", "Measurement",
           "ObserverSettings", "Plant", "RecedingHorizonController", "build_models", "mpc_solver", "perturbed_model",
           "planning_problem", "run_closed_loop", "scaled_ode"]
