"""Reference NLP solvers (IPOPT, fatrop via casadi.nlpsol) on the problem's transcription.

Both solve ``OptimalControlProblem.transcription`` (multiple shooting, stage-ordered
variables), i.e. exactly the problem DDP solves. Built once; ``solve`` may be called many
times with new x0, params and warm starts (primal; for IPOPT also the duals of a previous
IPOPT result, "nlp_lam_g"/"nlp_lam_x" in its multipliers).
"""
from __future__ import annotations

import dataclasses
import logging
import time
from typing import Any, Mapping

import casadi as ca
import numpy as np

from .._config import require, settings_from_mapping
from ..errors import InputError
from ..ocp import OptimalControlProblem
from .kkt import KKT_KEYS, KKTEvaluator, constraint_rows
from .result import LazyKKT, SolverResult, WarmStart

log = logging.getLogger(__name__)
_SRC = "ReferenceSettings"


@dataclasses.dataclass(frozen=True)
class ReferenceSettings:
    """Options for IpoptSolver / FatropSolver; ``plugin_options`` go to the plugin unchanged."""

    max_iterations: int = 1000
    tolerance: float = 1e-8
    constraint_tolerance: float = 1e-8
    print_level: int = 0
    expand: bool = True         # expand the NLP to SX: slower to set up, faster to evaluate (MX when False)
    plugin_options: Mapping[str, Any] = dataclasses.field(default_factory=dict)

    def __post_init__(self):
        require(isinstance(self.max_iterations, int) and self.max_iterations > 0, _SRC, "max_iterations",
                self.max_iterations, "expected an integer > 0")
        for name in ("tolerance", "constraint_tolerance"):
            v = getattr(self, name)
            require(isinstance(v, (int, float)) and np.isfinite(v) and v > 0, _SRC, name, v, "expected a number > 0")
        require(isinstance(self.print_level, int) and 0 <= self.print_level <= 12, _SRC, "print_level",
                self.print_level, "expected an integer in 0..12")
        require(isinstance(self.expand, bool), _SRC, "expand", self.expand, "expected True or False")
        require(isinstance(self.plugin_options, Mapping), _SRC, "plugin_options", self.plugin_options,
                "expected a mapping")

    @classmethod
    def from_mapping(cls, values: Mapping, source: str = _SRC) -> "ReferenceSettings":
        return settings_from_mapping(cls, values, source)


class _NlpSolver:
    plugin = ""
    dual_warm_start = False

    def __init__(self, problem: OptimalControlProblem, settings: ReferenceSettings | Mapping | None = None):
        if not isinstance(problem, OptimalControlProblem):
            raise InputError(type(self).__name__, "problem", type(problem).__name__,
                             "expected an OptimalControlProblem")
        if settings is None:
            settings = ReferenceSettings()
        elif isinstance(settings, Mapping):
            settings = ReferenceSettings.from_mapping(settings)
        self.problem, self.settings = problem, settings
        self.tr = problem.transcription
        self.kkt, self._rows = KKTEvaluator(problem), constraint_rows(problem)
        self._solvers: dict[bool, ca.Function] = {}
        self._solver(False)

    def _solver(self, warm_duals: bool) -> ca.Function:
        if warm_duals not in self._solvers:
            opts = {"expand": self.settings.expand, **self._options(warm_duals)}
            self._solvers[warm_duals] = ca.nlpsol(f"{self.plugin}_{self.problem.name}", self.plugin, self.tr.nlp, opts)
        return self._solvers[warm_duals]

    def _options(self, warm_duals: bool) -> dict:
        raise NotImplementedError

    def solve(self, x0, params=None, warm_start: WarmStart | SolverResult | None = None) -> SolverResult:
        pr, tr = self.problem, self.tr
        src = f"{type(self).__name__}.solve"
        x0 = pr.check_x0(x0, src)
        params = pr.check_params(params, src)
        args = {"p": tr.parameters(x0, params), "lbx": tr.lbx, "ubx": tr.ubx, "lbg": tr.lbg, "ubg": tr.ubg}
        warm_duals = False
        if warm_start is None:
            xs, us = np.tile(x0, (pr.horizon + 1, 1)), np.zeros((pr.horizon, pr.nu))
        else:
            xs, us = pr.check_trajectory(warm_start.xs, warm_start.us, src)
            m = warm_start.multipliers
            lam_g, lam_x = m.get("nlp_lam_g"), m.get("nlp_lam_x")
            if (self.dual_warm_start and lam_g is not None and np.shape(lam_g) == tr.lbg.shape
                    and np.shape(lam_x) == tr.lbx.shape):
                args.update(lam_g0=lam_g, lam_x0=lam_x)
                warm_duals = True
        args["x0"] = tr.pack(xs, np.clip(us, pr.u_lb, pr.u_ub))
        solver = self._solver(warm_duals)
        start = time.perf_counter()
        sol = solver(**args)
        solve_s = time.perf_counter() - start
        return self._result(solver, sol, solve_s, xs, us, x0, params)

    def _result(self, solver, sol, solve_s, xs0, us0, x0, params) -> SolverResult:
        tr = self.tr
        stats = solver.stats()
        w, g = np.asarray(sol["x"]).ravel(), np.asarray(sol["g"]).ravel()
        plugin_status = str(stats.get("return_status", "unknown"))
        status, reason = plugin_verdict(plugin_status, bool(stats.get("success", False)))
        cost = float(sol["f"])
        finite = bool(np.all(np.isfinite(w)) and np.all(np.isfinite(g)) and np.isfinite(cost))
        if not finite:
            status, reason, w = "failed", "numerical_error", tr.pack(xs0, us0)
            g, cost = np.full_like(g, np.inf), float("inf")
        xs, us = tr.unpack(w)
        viol = max(float(np.max(np.abs(g[tr.equality]), initial=0.0)),
                   float(np.max(g[~tr.equality], initial=0.0)),
                   float(np.max(tr.lbx - w, initial=0.0)), float(np.max(w - tr.ubx, initial=0.0)))
        mult = tr.split_constraint_multipliers(sol["lam_g"])
        mult.update(nlp_lam_g=np.asarray(sol["lam_g"]).ravel(), nlp_lam_x=np.asarray(sol["lam_x"]).ravel())
        duals = {k: np.array(mult[k], copy=True) for k in ("initial", "dynamics", "constraints", "terminal_constraints",
                                                           "nlp_lam_x")}
        kkt = LazyKKT(lambda: self._kkt(xs.copy(), us.copy(), x0, params.copy(), duals)) if finite else \
            dict.fromkeys(KKT_KEYS, float("inf"))
        certificate = None
        if status == "infeasible":  # the restoration phase converged to a local minimum of the violation
            certificate = {"penalty": [], "violation": [viol], "constraints": self._violated(g),
                           "method": f"{self.plugin} restoration phase: a local minimum of the constraint violation"}
        iterations = int(stats.get("iter_count", -1))
        log.info("%s %s after %d iterations: cost %.8g, %.3f ms", self.plugin, plugin_status, iterations, cost,
                 1e3 * solve_s)
        return SolverResult(solver=self.plugin, success=status == "converged", status=status, reason=reason,
                            message=plugin_status, certificate=certificate, kkt=kkt, xs=xs, us=us, cost=cost,
                            max_constraint_violation=viol, iterations=iterations, solve_s=solve_s, multipliers=mult,
                            info={"plugin_status": plugin_status, "t_wall_total": stats.get("t_wall_total")})

    def _violated(self, g) -> list[str]:
        """Names of the constraints the transcription's g violates ("dynamics" for the gaps)."""
        pr, tol = self.problem, self.settings.constraint_tolerance
        nx, ng, N = pr.nx, pr.n_constraints, pr.horizon
        stages = g[nx: nx + N * (nx + ng)].reshape(N, nx + ng)
        worst = np.concatenate([np.max(stages[:, nx:], axis=0, initial=-np.inf), g[nx + N * (nx + ng):]])
        names = [n for n, v in zip(self._rows[0] + self._rows[1], worst) if v > tol]
        if np.max(np.abs(stages[:, :nx]), initial=0.0) > tol:
            names.insert(0, "dynamics")
        return list(dict.fromkeys(names))

    def _kkt(self, xs, us, x0, params, mult) -> dict[str, float]:
        """The KKT residuals with the plugin's duals: costates lam_{k+1} = -(multiplier of x_{k+1} - f_k)."""
        costates = -np.vstack([mult["initial"], mult["dynamics"]])
        _, z = self.tr.unpack(mult["nlp_lam_x"])
        return self.kkt.residuals(xs, us, params, mult["constraints"], mult["terminal_constraints"], x0, costates, z)


# The plugins' return statuses (IPOPT's ApplicationReturnStatus, also fatrop's where they coincide) -> reason
_REASONS = {"Maximum_Iterations_Exceeded": "max_iterations", "Maximum_CpuTime_Exceeded": "max_time",
            "Maximum_WallTime_Exceeded": "max_time", "Restoration_Failed": "restoration_failed",
            "Search_Direction_Becomes_Too_Small": "line_search_failed", "Error_In_Step_Computation": "numerical_error",
            "Invalid_Number_Detected": "numerical_error", "Diverging_Iterates": "diverging_iterates",
            "Not_Enough_Degrees_Of_Freedom": "too_few_degrees_of_freedom", "User_Requested_Stop": "stopped"}
_INFEASIBLE = ("Infeasible_Problem_Detected",)  # IPOPT: restoration converged to a point of non-zero violation


def plugin_verdict(plugin_status: str, success: bool) -> tuple[str, str]:
    """(status, reason) of the contract from a plugin's return status and success flag."""
    if success:
        return "converged", ""
    if plugin_status in _INFEASIBLE:
        return "infeasible", "locally_infeasible"
    return "failed", _REASONS.get(plugin_status, plugin_status.lower() or "unknown")


class IpoptSolver(_NlpSolver):
    """IPOPT (interior point, MUMPS) on the transcription; warm starts primal and dual."""

    plugin = "ipopt"
    dual_warm_start = True

    def _options(self, warm_duals):
        s = self.settings
        ipopt = {"max_iter": s.max_iterations, "tol": s.tolerance, "constr_viol_tol": s.constraint_tolerance,
                 "print_level": s.print_level, "sb": "yes"}
        if warm_duals:
            ipopt.update(warm_start_init_point="yes", warm_start_bound_push=1e-9, warm_start_mult_bound_push=1e-9,
                         mu_init=1e-6)
        ipopt.update(s.plugin_options)
        return {"ipopt": ipopt, "print_time": False}


class FatropSolver(_NlpSolver):
    """fatrop (structure-exploiting interior point) with automatic OCP structure detection.

    Warm starts are primal only: the CasADi fatrop interface has no warm_start_init_point.
    """

    plugin = "fatrop"

    def _options(self, warm_duals):
        s = self.settings
        fatrop = {"max_iter": s.max_iterations, "tol": s.tolerance, "constr_viol_tol": s.constraint_tolerance,
                  "print_level": s.print_level}
        fatrop.update(s.plugin_options)
        return {"structure_detection": "auto", "equality": self.tr.equality.tolist(), "fatrop": fatrop,
                "print_time": False, "debug": False}
