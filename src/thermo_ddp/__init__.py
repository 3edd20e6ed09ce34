"""thermo-ddp: thermal-aware constrained DDP for torque-controlled humanoid arms."""
from .model.actuated import ActuatedArm, Trajectory, load_model
from .model.arm import LEFT_ARM, ArmSettings, build_arm
from .errors import InputError
from .tasks.lift import LiftPlan, LiftSettings, compare_limits, plan_lift
from .mpc import MPCSettings, run_closed_loop
from .model.parameters import JointParameters, load_parameters, save_parameters
from .model.thermal import ThermalNetwork, network_from_parameters, one_node_response

__all__ = [
    "ActuatedArm", "ArmSettings", "InputError", "JointParameters", "LEFT_ARM", "LiftPlan", "LiftSettings",
    "MPCSettings", "ThermalNetwork", "Trajectory", "compare_limits", "plan_lift", "run_closed_loop",
    "build_arm", "load_model", "load_parameters", "network_from_parameters", "one_node_response",
    "save_parameters",
]
