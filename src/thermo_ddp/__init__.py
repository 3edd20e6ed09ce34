"""thermo-ddp: thermal-aware constrained DDP for torque-controlled humanoid arms."""
from .actuated_arm import ActuatedArm, Trajectory, load_model
from .arm import LEFT_ARM, ArmSettings, build_arm
from .errors import InputError
from .lift import LiftPlan, LiftSettings, compare_limits, plan_lift
from .mpc import MPCSettings, run_closed_loop
from .parameters import JointParameters, load_parameters, save_parameters
from .thermal import ThermalNetwork, network_from_parameters, one_node_response

__all__ = [
    "ActuatedArm", "ArmSettings", "InputError", "JointParameters", "LEFT_ARM", "LiftPlan", "LiftSettings",
    "MPCSettings", "ThermalNetwork", "Trajectory", "compare_limits", "plan_lift", "run_closed_loop",
    "build_arm", "load_model", "load_parameters", "network_from_parameters", "one_node_response",
    "save_parameters",
]
