"""The longest feasible hold of a lift in few complete solves.

Each probe is a complete optimisation with a verdict (:mod:`thermo_ddp.tasks.attempts`). Where to probe
comes first from the caller (``plan_lift``: the time to the limit holding at the goal from the start's
temperatures, a little long), then from a thermal-only prediction (milliseconds): the longest hold whose
winding stays under the limit when the last plan's currents of the lift, the hold and the lowering are
replayed with the hold stretched or cut (what the optimiser does on the lift, the hold band and the lowering). The
prediction from an infeasible plan near the boundary is within a knot or two (it replays what the optimiser
does when the limit binds; the first probe's by about half its distance, see :func:`_next_guess`);
from a feasible plan that does not reach the limit it is short. When it misses on the same side twice the
probes gallop (steps doubling); bisection takes over after :data:`GUIDED_PROBES` probes. The infeasible verdict
one knot past the longest hold is stated only from that hold's plan stretched and its multipliers
(:func:`boundary_warm_start`; solved again when it came from another start); that hold's plan, when its warm
start reached a verdict only through a later rung of the same solver, is first solved again from the cold
guess, the lower-cost plan kept (:meth:`_Search.settle`). The default 40 kg searches take 3 solves each: 98 DDP
iterations at 84 °C and 110 at 140 °C (4 solves at 84 °C with a 1-knot bias; 6 and 4 solves by galloping and
bisection; benchmarks/README.md).
"""
from __future__ import annotations

import dataclasses
import logging
from typing import Callable, Mapping

import numpy as np

from ..solvers import SolverResult, WarmStart
from .attempts import Outcome
from .thermal_hold import thermal_trajectory, time_to_limit_by_joint, winding_indices
from .verdicts import binding_constraints, cause_class, deciding_constraints

log = logging.getLogger(__name__)
GUIDED_PROBES = 5   # probes placed by the prediction (galloping when it misses twice); bisection after them


@dataclasses.dataclass(frozen=True)
class HoldSearch:
    """The probes of :func:`longest_feasible_hold`: hold (knots) -> (problem, outcome)."""

    knots: int          # the longest feasible hold in knots; -1 when not even touching the goal is feasible
    probes: Mapping[int, tuple[object, Outcome]]
    failed: int | None = None   # the hold (knots) whose solves reached no verdict (the search stopped there)
    replaced: tuple[Outcome, ...] = ()   # verdicts solved again (the boundary confirmed): counted, not used

    @property
    def best(self) -> tuple[object, Outcome]:
        """The failed probe, else the longest feasible one, else the shortest infeasible one."""
        if self.failed is not None:
            return self.probes[self.failed]
        return self.probes[self.knots if self.knots >= 0 else min(self.probes)]

    @property
    def results(self) -> list[SolverResult]:
        return [r for o in (*self.replaced, *(o for _, o in self.probes.values())) for r in o.results]

    @property
    def solve_s(self) -> float:
        return sum(r.solve_s for r in self.results)


def _stretched(values: np.ndarray, first: int, hold: int, knots: int, held: np.ndarray) -> np.ndarray:
    """Per-step ``values`` of a plan holding ``hold`` steps from step ``first``, with the hold made ``knots``
    steps long (``held`` repeated), cut or padded with the last row to the same length."""
    out = np.vstack([values[:first], np.tile(held, (knots, 1)), values[first + hold:]])
    rows = values.shape[0]
    return out[:rows] if out.shape[0] >= rows else np.vstack([out, np.tile(out[-1], (rows - out.shape[0], 1))])


def _moved(values: np.ndarray, end: int, shift: int) -> np.ndarray:
    """Rows of ``values`` with the hold's end moved by ``shift`` knots: the row at ``end`` repeated (shift > 0)
    or the rows before it dropped (shift < 0), the last row repeated or the last rows cut to the same length."""
    values = np.asarray(values)
    if shift >= 0:
        out = np.concatenate([values[:end], np.repeat(values[end:end + 1], shift, axis=0), values[end:]])
    else:
        out = np.concatenate([values[:end + shift], values[end:], np.repeat(values[-1:], -shift, axis=0)])
    return np.ascontiguousarray(out[:values.shape[0]])


def stretched_warm_start(plan: tuple[object, SolverResult], knots: int) -> WarmStart:
    """``plan``'s trajectories with its hold made ``knots`` long: everything after the hold moves with the hold's
    end, so the lowering starts where the probe's reference lowers (not the neighbour's solution as it is, whose
    lowering is off by the knots between them). Its multipliers are left (see :func:`boundary_warm_start`)."""
    (end, shift), result = _hold_move(plan[0], knots), plan[1]
    return WarmStart(_moved(result.xs, end, shift), _moved(result.us, end, shift))


def _hold_move(src, knots: int) -> tuple[int, int]:
    """(the knot where ``src``'s hold ends, the knots it moves by) when that hold is made ``knots`` long."""
    return src.hold_knots[1], knots - (src.hold_knots[1] - src.hold_knots[0])


def boundary_warm_start(plan: tuple[object, SolverResult], knots: int) -> WarmStart:
    """:func:`stretched_warm_start` with ``plan``'s constraint multipliers moved with the hold's end and each
    row's penalty halfway (geometric) back to the smallest: the confirmation one knot past the longest feasible
    hold, from that hold's plan. Measured on the 40 kg searches (benchmarks/README.md): the infeasible verdict
    in 20 iterations at 84 °C and 33 at 140 °C against 46 and 57 from the trajectories alone; with the
    penalties kept, or from an infeasible neighbour, 200 iterations and no verdict (the solve is then capped:
    :data:`thermo_ddp.tasks.attempts.WARM_MULTIPLIER_ITERATIONS`)."""
    (end, shift), m = _hold_move(plan[0], knots), plan[1].multipliers
    warm = stretched_warm_start(plan, knots)
    if m.get("constraints") is None or m.get("penalty") is None:  # a solver without an augmented Lagrangian
        return warm
    rho = np.asarray(m["penalty"], dtype=float)
    return WarmStart(warm.xs, warm.us, {"constraints": _moved(m["constraints"], end, shift),
                                        "terminal_constraints": m.get("terminal_constraints"),
                                        "penalty": np.sqrt(rho * rho.min())})


def _peak_winding(lp, current: np.ndarray, speed: np.ndarray) -> float:
    temps = thermal_trajectory(lp.model, current, speed, lp.x0[2 * lp.model.nu:], lp.settings.dt_s)
    return float(temps[:, winding_indices(lp.model)].max())


def _thermal(probe, result: SolverResult) -> bool:
    """A thermal constraint among those that decide an infeasible probe (violated, or at its bound)."""
    names = deciding_constraints(probe, result, violated=True)
    names += [k for k in binding_constraints(probe, result) if k not in names]
    return any(cause_class(k) == "thermal" for k in names)


def _at_limit(lp, result: SolverResult, margin_c: float = 0.5) -> bool:
    return float(result.xs[:, [lp.model.index(j, "winding_c") for j in lp.model.joints]].max()) >= (
        lp.settings.limit_c - margin_c)


def _arrival_knots(lp, probe, result: SolverResult) -> int:
    """Knots of holding the least current of the band, from ``result``'s state on arrival, until the limit."""
    held, joint = _replay(lp, (probe, result))[4], lp.model.joints[0]
    horizon = (lp.hold_knots[1] - lp.hold_knots[0] + 1) * lp.settings.dt_s
    # the model's own thermal state (a robust problem's first scenario: its later scenarios follow it in x)
    ttl = time_to_limit_by_joint(lp.model, held, result.xs[probe.hold_knots[0], 2 * lp.model.nu:lp.model.nx],
                                 {joint: lp.settings.limit_c}, horizon, lp.settings.dt_s)[joint]
    return int(min(ttl, horizon) / lp.settings.dt_s)


def predicted_peak_winding_c(lp, plan: tuple[object, SolverResult], knots: int) -> float:
    """The winding's peak replaying ``plan``'s currents (its problem and result) with a hold of ``knots``."""
    current, speed, first, hold, held = _replay(lp, plan)
    return _peak_winding(lp, _stretched(current, first, hold, knots, held),
                         _stretched(speed, first, hold, knots, np.zeros_like(held)))


def _replay(lp, plan):
    """(current, speed, hold start, hold knots, held current) of ``plan``. The held current is the least that
    holds the payload still inside the hold band (the optimiser's hold)."""
    s = lp.settings
    held = min((lp.model.static_current_a([q]) for q in (s.goal_rad - s.hold_tolerance_rad,
                                                         s.goal_rad + s.hold_tolerance_rad)), key=lambda i: abs(i[0]))
    src, result = plan
    speed = result.xs[:-1, [lp.model.index(j, "v_rad_s") for j in lp.model.joints]]
    return result.us, speed, src.hold_knots[0], src.hold_knots[1] - src.hold_knots[0], held


def predicted_hold_knots(lp, plan: tuple[object, SolverResult]) -> int:
    """The longest hold (knots, up to the requested one; -1: none) whose replayed currents keep the winding
    under ``lp.settings.limit_c``: the currents of ``plan`` (its problem and result). The search starts at
    ``plan``'s own hold and gallops outwards (the answer is usually a few knots away), then bisects."""
    top = lp.hold_knots[1] - lp.hold_knots[0]

    def fits(k):
        return predicted_peak_winding_c(lp, plan, k) <= lp.settings.limit_c

    lo, hi = _gallop(fits, min(max(plan[0].hold_knots[1] - plan[0].hold_knots[0], 0), top), top)
    while hi - lo > 1:
        mid = (lo + hi) // 2
        lo, hi = (mid, hi) if predicted_peak_winding_c(lp, plan, mid) <= lp.settings.limit_c else (lo, mid)
    return lo


def _warm_start(probes: Mapping[int, tuple[object, Outcome]], knots: int,
                verdicts: bool = True) -> tuple[int | None, WarmStart | None]:
    """(the probe it comes from, the warm start): the nearest solved probe's solution stretched to ``knots``
    (with its multipliers from a feasible one one knot below: :func:`boundary_warm_start`); the nearest
    feasible one first, unless an infeasible one is nearer by more than a knot. Measured on the 40 kg 140 °C
    search (benchmarks/README.md): the feasible probe 3 knots below the infeasible first one took 59
    iterations from its plan stretched against 82 from the plan as it is (at 46.1 kg, 127.6 °C, where the
    unstretched plan was chosen for, the search now takes 3 solves, none retried). Without ``verdicts`` (a
    controller's real-time search) an infeasible probe's plan is taken as it is and no multipliers are given:
    the receding-horizon tests are measured with those starts."""
    if not probes:
        return None, None
    feasible = [k for k, (_, o) in probes.items() if o.feasible]
    near = min(probes, key=lambda k: abs(k - knots))
    if feasible and abs(min(feasible, key=lambda k: abs(k - knots)) - knots) <= abs(near - knots) + 1:
        near = min(feasible, key=lambda k: abs(k - knots))
    problem, outcome = probes[near]
    if not verdicts and not outcome.feasible:
        return near, WarmStart(outcome.result.xs, outcome.result.us)
    boundary = verdicts and outcome.feasible and near == knots - 1
    return near, (boundary_warm_start if boundary else stretched_warm_start)((problem, outcome.result), knots)


def _gallop(fits: Callable[[int], bool], start: int, top: int) -> tuple[int, int]:
    """A bracket (lo, hi) with fits(lo) (or lo = -1) and not fits(hi) (or hi = top + 1), galloping from
    ``start`` (steps doubling) toward the side where the answer lies."""
    step = 1
    if fits(start):
        lo = start
        while lo < top and fits(min(lo + step, top)):
            lo, step = min(lo + step, top), 2 * step
        return lo, (min(lo + step, top) if lo < top else top + 1)
    hi = start
    while hi > 0 and not fits(max(hi - step, 0)):
        hi, step = max(hi - step, 0), 2 * step
    return (max(hi - step, 0) if hi > 0 else -1), hi


class _Search:
    """The probes of one search: hold (knots) -> (problem, outcome), and the probe each was warm-started from."""

    def __init__(self, lp, solve: Callable[[object, WarmStart | None], Outcome], verdicts: bool = True):
        self.lp, self.solve, self.verdicts = lp, solve, verdicts
        self.probes: dict[int, tuple[object, Outcome]] = {}
        self.source: dict[int, int | None] = {}
        self.replaced: list[Outcome] = []
        self.settled: set[int] = set()

    def run(self, knots: int, source: int | None = None) -> Outcome:
        """Solve the probe holding ``knots``, from probe ``source``'s plan stretched (default: the nearest)."""
        probe = self.lp.with_hold(knots * self.lp.settings.dt_s)
        if source is None:
            source, warm = _warm_start(self.probes, knots, self.verdicts)
        else:  # the confirmation: from the boundary's plan and multipliers
            warm = boundary_warm_start((self.probes[source][0], self.probes[source][1].result), knots)
        if knots in self.probes:
            self.replaced.append(self.probes[knots][1])
        self.probes[knots], self.source[knots] = (probe, self.solve(probe, warm)), source
        log.info("hold %.1f s: %s", probe.hold_s, self.probes[knots][1].verdict or "no verdict")
        return self.probes[knots][1]

    def unconfirmed(self, lo: int, hi: int) -> bool:
        """The boundary's infeasible verdict (``hi`` = ``lo`` + 1) was not reached from ``lo``'s feasible plan
        stretched: the four certificates the random requests found local (DDP's longest hold two or more knots
        short of IPOPT's, benchmarks/README.md) came from a cold start or an infeasible neighbour's plan."""
        return lo >= 0 and hi == lo + 1 and hi in self.probes and self.source[hi] != lo

    def settle(self, knots: int) -> None:
        """Solve the longest feasible hold ``knots`` once more from the cold initial guess when its plan came
        from a warm start only through a later rung of the same solver (the first, from the neighbour's
        multipliers, reached no verdict), and keep the lower-cost feasible plan: the answer should not hang on
        a neighbour's start that did not hold. A plan of the ladder's reference solver (IPOPT) is kept as it
        is: from the cold guess DDP then went down the whole ladder again (49.7 kg, 96 °C: 4 more solves, the
        same cost). Measured at 40 kg, 85.9 °C (benchmarks/README.md): 604.59 from the neighbour's
        trajectories, 603.21 from the cold guess (IPOPT 603.21), the boundary then confirmed from it in one
        solve instead of five."""
        if knots < 0 or knots in self.settled:
            return
        self.settled.add(knots)
        probe, outcome = self.probes[knots]
        if len(outcome.attempts) < 2 or self.source[knots] is None:
            return
        if outcome.result.solver != outcome.attempts[0][1].solver:  # the reference's plan
            return
        cold = self.solve(probe, None)
        log.info("hold %.1f s again from the cold guess: %s", probe.hold_s, cold.verdict or "no verdict")
        if cold.feasible and cold.result.cost < outcome.result.cost:
            self.replaced.append(outcome)
            self.probes[knots], self.source[knots] = (probe, cold), None
        else:
            self.replaced.append(cold)

    def result(self, lo: int, failed: int | None = None) -> "HoldSearch":
        return HoldSearch(lo, self.probes, failed, tuple(self.replaced))


def _next_guess(lp, knots: int, outcome: Outcome, lo: int, hi: int, step: int, first: bool = False) -> int:
    """Where the next probe goes after ``outcome`` at ``knots`` (``first``: the search's first probe): the
    thermal replay's prediction."""
    probe = lp.with_hold(knots * lp.settings.dt_s)
    predicted = predicted_hold_knots(lp, (probe, outcome.result))
    if outcome.feasible and not _at_limit(lp, outcome.result):
        # a plan short of the limit heats more on its lift and lowering than one at the boundary, so its replay
        # is short: take the time to the limit from its arrival (long: the lowering's heat aside) when longer
        predicted = max(predicted, _arrival_knots(lp, probe, outcome.result))
    if not outcome.feasible and predicted >= knots and not _thermal(probe, outcome.result):
        return 0  # the heat neither decides nor binds: a shorter hold will not help, try touching the goal
    # the replay of an infeasible plan d >= 2 knots past its prediction is a knot optimistic (its hold and
    # lowering still give way); the first probe's (from the cold start, placed a little long) by about d / 2,
    # rounded down: a probe short of the boundary costs more (the short replays of feasible plans gallop).
    # Measured on 12 requests (20-60 kg, 70-140 °C, benchmarks/README.md)
    d = knots - predicted
    bias = 0 if d < 2 else max(1, d // 2) if first else 1
    return max(predicted, lo + step) if outcome.feasible else min(predicted - bias, hi - step)


def longest_feasible_hold(lp, solve: Callable[[object, WarmStart | None], Outcome], first_knots: int,
                          stop_without_verdict: bool = True) -> HoldSearch:
    """The longest hold, up to the requested one (the fixed horizon), with a feasible plan.

    ``solve(problem, warm_start)`` gives a probe's :class:`Outcome`; the first probe holds ``first_knots``.
    Every verdict is a complete optimisation, warm-started from the nearest solved probe's trajectories; the
    infeasible verdict one knot past the longest feasible hold is confirmed from that hold's plan stretched
    (:meth:`_Search.unconfirmed`). A probe without a verdict stops the search (``failed``), or with
    ``stop_without_verdict`` off (a controller that needs some verified plan) counts as not feasible: the
    search goes on to shorter holds, and the result is then the longest hold verified feasible, not a verdict
    on longer ones (so nothing is confirmed: a real-time review spends no solve on it)."""
    search, top = _Search(lp, solve, stop_without_verdict), lp.hold_knots[1] - lp.hold_knots[0]
    lo, hi, guess, step, last = -1, top + 1, first_knots, 1, None
    while True:
        if stop_without_verdict and hi - lo <= 1:
            search.settle(lo)
        if not (hi - lo > 1 or (stop_without_verdict and search.unconfirmed(lo, hi))):
            break
        confirm = hi - lo <= 1
        guided = len(search.probes) < GUIDED_PROBES
        knots = hi if confirm else int(np.clip(guess, lo + 1, hi - 1)) if guided else (lo + hi) // 2
        outcome = search.run(knots, lo if confirm else None)
        if outcome.verdict is None and stop_without_verdict:
            return search.result(lo, failed=knots)
        if confirm and outcome.feasible:  # the next infeasible probe up, or the request, is the bracket
            hi = min([k for k, (_, o) in search.probes.items() if k > knots and not o.feasible], default=top + 1)
        lo, hi = (knots, hi) if outcome.feasible else (lo, knots)
        same_side = outcome.verdict == last and (outcome.feasible or len(search.probes) > 2)
        step = 2 * step if same_side else 1   # the same side again: gallop
        last = outcome.verdict
        # the first probe's bias is measured on plans (verdicts); a controller's real-time search keeps a knot
        guess = _next_guess(lp, knots, outcome, lo, hi, step, first=stop_without_verdict and len(search.probes) == 1)
    return search.result(lo)
