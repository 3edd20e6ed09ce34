"""thermo-ddp: thermal-aware constrained DDP for torque-controlled humanoid arms."""
from importlib.metadata import PackageNotFoundError, version as _version

try:  # the installed distribution's version (the wheel's), one source: pyproject.toml
    __version__ = _version("thermo-ddp")
except PackageNotFoundError:  # imported from a source tree that was never installed
    __version__ = "0+unknown"

from .model.actuated import ActuatedArm, Trajectory, load_model
from .model.arm import LEFT_ARM, ArmSettings, build_arm
from .errors import InputError
from .monitor import ArmMonitor, monitor_bag, monitor_recordings
from .tasks.limits import DEFAULT_HOLD_S
from .tasks.lift import LiftPlan, LiftSettings, compare_limits, plan_lift
from .tasks.whole_arm import WholeArmPlan, WholeArmSettings, plan_whole_arm
from .tasks.experiment import ExperimentDesign, ExperimentSettings, design_experiment
from .mpc import MPCSettings, run_closed_loop
from .model.parameters import JointParameters, load_parameters, save_parameters
from .model.thermal import ThermalNetwork, network_from_parameters, one_node_response

__all__ = [
    "ActuatedArm", "ArmMonitor", "ArmSettings", "DEFAULT_HOLD_S", "ExperimentDesign", "ExperimentSettings",
    "InputError", "JointParameters", "LEFT_ARM",
    "LiftPlan", "LiftSettings", "MPCSettings", "ThermalNetwork", "Trajectory", "WholeArmPlan", "WholeArmSettings",
    "compare_limits", "design_experiment", "plan_lift", "plan_whole_arm", "run_closed_loop", "build_arm", "load_model",
    "load_parameters", "monitor_bag", "monitor_recordings", "network_from_parameters", "one_node_response",
    "save_parameters",
]
