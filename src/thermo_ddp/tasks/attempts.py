"""Solving a task until a solve reaches a verdict: a failed solve is retried, never read as a statement
about the robot.

The ladder (issue 23): the task's solver from its guess (a guess carrying a neighbour's multipliers first
from them, for at most :data:`WARM_MULTIPLIER_ITERATIONS` iterations, then from its trajectories alone); for
DDP then a regularised restart (Gauss-Newton
iLQR, whose Hessians are positive semi-definite by construction, with a regularised first pass), the same
from another initial guess (the arm at rest, holding its start), and last the reference solver (IPOPT on
the same transcription). When none reaches a verdict the task's plan is ``failed``.
"""
from __future__ import annotations

import dataclasses
import functools
import logging
from typing import Callable, Sequence

import numpy as np

from ..ocp import OptimalControlProblem
from ..solvers import DDPSettings, DDPSolver, FatropSolver, IpoptSolver, SolverResult, WarmStart
from .problem import TaskProblem
from .verdicts import verdict

log = logging.getLogger(__name__)
RESTART_REG = 1e-4   # first-pass Quu regularisation of the restart (the default starts at 0)
# A DDP solve from a neighbour's multipliers that reaches no verdict in this many iterations is dropped for the
# same solve from the trajectories alone. Measured on the longest-hold searches' probes one knot past a feasible
# one (benchmarks/README.md; 40 kg at 84 and 140 °C, 30 kg at 100 °C, 55 kg at 120 °C): 20, 33, 33, 47 and 45
# iterations from the multipliers against 46, 57, 72, 39 and 50 from the trajectories; from an infeasible or a
# longer neighbour's multipliers 200 iterations without a verdict, so those are never given.
WARM_MULTIPLIER_ITERATIONS = 50


@dataclasses.dataclass(frozen=True)
class Outcome:
    """The solves of one problem: ``result`` is the one with a verdict (the last one when none had)."""

    result: SolverResult
    verdict: str | None     # "feasible", "infeasible" or None (no solve reached a verdict)
    attempts: tuple[tuple[str, SolverResult], ...]

    @property
    def feasible(self) -> bool:
        return self.verdict == "feasible"

    @property
    def results(self) -> list[SolverResult]:
        return [r for _, r in self.attempts]

    @property
    def solve_s(self) -> float:
        return sum(r.solve_s for r in self.results)

    def tried(self) -> str:
        """``ddp: failed (regularisation_failed); ipopt: converged`` (each attempt's status and reason)."""
        return "; ".join(f"{name}: {r.status}" + (f" ({r.reason})" if r.reason else "") for name, r in self.attempts)


def solve_until_verdict(attempts: Sequence[tuple[str, Callable[[], SolverResult]]]) -> Outcome:
    """Run ``attempts`` (name, solve) in order until one reaches a verdict (:func:`verdict`)."""
    done: list[tuple[str, SolverResult]] = []
    for name, run in attempts:
        result = run()
        done.append((name, result))
        found = verdict(result)
        if found is not None:
            return Outcome(result, found, tuple(done))
        log.info("%s: %s (%s), no verdict: retrying", name, result.status, result.reason)
    return Outcome(done[-1][1], None, tuple(done))


def rest_guess(tp: TaskProblem) -> WarmStart:
    """Another initial guess: the arm at rest at its initial state, with the currents that hold it there."""
    xs = np.tile(tp.x0, (tp.params.shape[0], 1))
    q0 = tp.x0[[tp.model.index(j, "q_rad") for j in tp.model.joints]]
    return WarmStart(xs, np.tile(tp.model.static_current_a(q0), (tp.params.shape[0] - 1, 1)))


class SolverLadder:
    """The solvers of one problem structure's retries, each built when first needed: ``primary`` (a solver
    instance) and the restart's DDP settings (default: the primary's), Gauss-Newton and regularised."""

    def __init__(self, problem: OptimalControlProblem, primary, ddp_settings: DDPSettings | None = None):
        self.problem, self.primary = problem, primary
        ddp = primary if isinstance(primary, DDPSolver) else getattr(primary, "solver", None)
        default = ddp.settings if isinstance(ddp, DDPSolver) else DDPSettings()
        self.ddp_settings = ddp_settings or default

    @functools.cached_property
    def restart(self) -> DDPSolver:
        settings = dataclasses.replace(self.ddp_settings, full_second_order=False, reg_init=RESTART_REG)
        return DDPSolver(self.problem, settings)

    @functools.cached_property
    def reference(self) -> IpoptSolver:
        return IpoptSolver(self.problem)

    def solve(self, tp: TaskProblem, guess: WarmStart, reference: bool = True) -> Outcome:
        """The ladder on ``tp`` from ``guess``: DDP's four steps (the last, IPOPT, unless ``reference`` is off:
        e.g. in a real-time loop), or a reference solver from two guesses."""
        x0, p, first = tp.x0, tp.params, self.primary
        plain = WarmStart(guess.xs, guess.us)
        restarts = [("ddp regularised restart", lambda: self.restart.solve(x0, p, plain)),
                    ("ddp regularised from rest", lambda: self.restart.solve(x0, p, rest_guess(tp)))]
        if not isinstance(first, DDPSolver):  # a reference solver, or a wrapper of one (e.g. a fault injector)
            name = first.plugin if isinstance(first, (IpoptSolver, FatropSolver)) else type(first).__name__
            wrapped_ddp = isinstance(getattr(first, "solver", None), DDPSolver)  # its restarts too, as unwrapped
            return solve_until_verdict(((name, lambda: first.solve(x0, p, guess)),
                                        (f"{name} from rest", lambda: first.solve(x0, p, rest_guess(tp))),
                                        *(restarts if wrapped_ddp else ())))
        rungs = [("ddp", lambda: first.solve(x0, p, plain))]
        if guess.multipliers:
            rungs.insert(0, ("ddp from the multipliers", lambda: first.solve(x0, p, guess, callback=_capped)))
        rungs += restarts
        if reference:
            rungs.append(("ipopt", lambda: self.reference.solve(x0, p, WarmStart(guess.xs, guess.us))))
        return solve_until_verdict(rungs)


def _capped(view) -> bool:
    """The callback that stops a solve after :data:`WARM_MULTIPLIER_ITERATIONS` iterations."""
    return view.iteration >= WARM_MULTIPLIER_ITERATIONS
