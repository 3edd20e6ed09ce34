"""Receding-horizon control of the elbow lift (plant, observer, controller; do-mpc style separation)."""
from .closed_loop import ClosedLoopResult, build_models, run_closed_loop
from .controller import ControlStep, RecedingHorizonController, mpc_solver, planning_problem
from .faults import FaultySolver
from .observer import CasingMonitor, ExtendedKalmanFilter, ObserverSettings, scaled_ode, stuck_run_length
from .plant import Measurement, Plant, perturbed_model
from .settings import (ControllerSettings, EstimatorSettings, MPCSettings, PlantSettings, ScenarioSettings,
                       SensorSettings)

__all__ = ["CasingMonitor", "ClosedLoopResult", "ControlStep", "ControllerSettings", "EstimatorSettings",
           "ExtendedKalmanFilter", "FaultySolver", "MPCSettings", "Measurement", "ObserverSettings", "Plant",
           "PlantSettings", "RecedingHorizonController", "ScenarioSettings", "SensorSettings", "build_models",
           "mpc_solver", "perturbed_model", "planning_problem", "run_closed_loop", "scaled_ode", "stuck_run_length"]
