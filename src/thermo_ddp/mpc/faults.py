"""Injected solver faults for closed-loop tests: a wrapper that makes chosen solves fail or come too late."""
from __future__ import annotations

import dataclasses

import numpy as np

from ..solvers import SolverResult, WarmStart


class FaultySolver:
    """Wraps a solver; solve number ``n`` (0-based, in call order) is made to fail when ``n`` is in
    ``fail_calls`` or with ``failure_probability``, and to take ``late_s`` (its result unchanged, its
    reported time ``late_s``: a deadline miss) when in ``late_calls`` or with ``late_probability``.
    A failed solve returns the warm start with infinite cost and violation, status ``failed``, reason
    ``injected_failure``."""

    def __init__(self, solver, fail_calls=(), late_calls=(), failure_probability: float = 0.0,
                 late_probability: float = 0.0, late_s: float = 1.0, seed: int = 0):
        self.solver, self.problem = solver, solver.problem
        self.fail_calls, self.late_calls = set(fail_calls), set(late_calls)
        self.failure_probability, self.late_probability, self.late_s = failure_probability, late_probability, late_s
        self.rng = np.random.default_rng(seed)
        self.calls = 0
        self.injected = {"failed": [], "late": []}

    def solve(self, x0, params=None, warm_start=None) -> SolverResult:
        n, self.calls = self.calls, self.calls + 1
        fail = n in self.fail_calls or self.rng.random() < self.failure_probability
        late = n in self.late_calls or self.rng.random() < self.late_probability
        if fail:
            self.injected["failed"].append(n)
            return self._failure(x0, warm_start)
        result = self.solver.solve(x0, params, warm_start)
        if late:
            self.injected["late"].append(n)
            result = dataclasses.replace(result, solve_s=max(result.solve_s, self.late_s))
        return result

    def _failure(self, x0, warm) -> SolverResult:
        pr = self.problem
        if isinstance(warm, (WarmStart, SolverResult)):
            xs, us = np.array(warm.xs, float), np.array(warm.us, float)
        else:
            xs, us = np.tile(np.asarray(x0, float), (pr.horizon + 1, 1)), np.zeros((pr.horizon, pr.nu))
        return SolverResult(solver="injected", success=False, status="failed", reason="injected_failure",
                            message="failure injected by FaultySolver", xs=xs, us=us, cost=float("inf"),
                            max_constraint_violation=float("inf"), iterations=0, solve_s=0.0)
