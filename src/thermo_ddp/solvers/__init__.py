"""Optimal-control solvers on OptimalControlProblem: constrained DDP and IPOPT/fatrop references."""
from .ddp import DDPSettings, DDPSolver
from .reference import FatropSolver, IpoptSolver, ReferenceSettings
from .result import SolverResult, WarmStart

__all__ = ["DDPSettings", "DDPSolver", "FatropSolver", "IpoptSolver", "ReferenceSettings", "SolverResult",
           "WarmStart"]
