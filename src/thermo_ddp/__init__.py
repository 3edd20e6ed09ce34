"""thermo-ddp: thermal-aware constrained DDP for torque-controlled humanoid arms."""
from .errors import InputError

__all__ = ["InputError"]
