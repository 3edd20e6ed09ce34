"""Robust receding-horizon planning: the controller's hold kept to what every motor of an uncertainty set
survives, with the set narrowing as the observer learns.

With ``ControllerSettings.robust_uncertainty`` = FRACTION the set is the planner's file values within
+-FRACTION (:meth:`~thermo_ddp.tasks.uncertainty.UncertaintySet.from_fraction`: every thermal capacity and
resistance, the drive's losses, the winding resistance). The EKF estimates one common scale ``s`` of the
thermal resistances (:mod:`thermo_ddp.mpc.observer`); each resistance's interval is narrowed to
``s +- robust_sigmas * std(s)`` times the file's value (:meth:`RobustHold.narrow`, called by the closed loop
every period): the set shrinks as the estimate's variance does. The other values keep their prior intervals
(the observer does not estimate them); without the observer's scale (``estimate_resistance_scale`` off) the
set stays the prior.

At the cold plan and then every ``robust_replan_s`` while lifting or holding (:meth:`RobustHold.review`):
the worst motor of the current set for the accepted plan (:class:`~thermo_ddp.tasks.uncertainty.WorstCase`,
every motor from the planning state: the estimate, raised by the controller's tightening); when its winding
exceeds the planning limit by more than :data:`~thermo_ddp.tasks.robust.TOLERANCE_K`, the hold is cut to
where it crosses and re-solved until no motor does; otherwise a hold shorter than the task's is lengthened
by one ``hold_step_s`` when the re-solve with it is accepted and safe for the set. The re-solves themselves
stay nominal (one model): the set decides the hold, the model the current. A review's searches and re-solves
are not counted against ``max_solve_s`` (the period's real-time budget): on a robot they belong in a slower
thread beside the loop.
"""
from __future__ import annotations

import dataclasses
import logging

import numpy as np

from ..solvers import SolverResult, WarmStart
from ..tasks.lift import LIFT_PARAMETERS
from ..tasks.robust import TOLERANCE_K, env_of
from ..tasks.uncertainty import UncertaintySet, WorstCase, WorstMotor, scenario_step

log = logging.getLogger(__name__)

MAX_CUTS = 6  # hold cuts per review (each a re-solve and a worst-motor search)


class RobustHold:
    """The uncertainty set of a receding-horizon controller and the reviews of its hold (module docstring)."""

    def __init__(self, controller):
        lp, c = controller.lp, controller.settings.controller
        model = lp.model
        self.prior = UncertaintySet.from_fraction(model.params[model.joints[0]], c.robust_uncertainty)
        self.uset = self.prior
        step = scenario_step(model, self.prior.keys, lp.settings.dt_s, lp.settings.integrator,
                             LIFT_PARAMETERS.size, env_of)
        self.worst = WorstCase(model, self.prior, step, model.index(model.joints[0], "winding_c"),
                               lp.x0[2 * model.nu:])
        self.sigmas = c.robust_sigmas
        self.every = max(1, int(round(c.robust_replan_s / lp.settings.dt_s)))
        self._resistances = np.array([k.startswith("thermal.") and k.endswith("_k_per_w") for k in self.prior.keys])
        self.last: WorstMotor | None = None

    def narrow(self, scale: float, scale_std: float) -> UncertaintySet:
        """The set with every thermal resistance within ``scale +- robust_sigmas * scale_std`` times the file's
        value, inside its prior interval (when the two do not meet, the observer's interval: the data
        override the prior)."""
        low, high = self.prior.low.copy(), self.prior.high.copy()
        r = self._resistances
        band_low = self.prior.nominal[r] * max(scale - self.sigmas * scale_std, 0.0)
        band_high = self.prior.nominal[r] * (scale + self.sigmas * scale_std)
        lo, hi = np.maximum(low[r], band_low), np.minimum(high[r], band_high)
        meet = lo <= hi
        low[r], high[r] = np.where(meet, lo, band_low), np.where(meet, hi, band_high)
        self.uset = dataclasses.replace(self.prior, low=low, high=high,
                                        label=f"{self.prior.label}, resistances s = {scale:.3f} +- "
                                              f"{self.sigmas * scale_std:.3f}")
        return self.uset

    def due(self, k: int) -> bool:
        return k % self.every == 0

    def search(self, controller, x: np.ndarray, result: SolverResult) -> WorstMotor:
        """The worst motor of the current set for ``result`` (the plan of the window at ``controller.k``)."""
        n, amb = controller.lp.model.nu, self._ambient(controller)
        self.last = self.worst.with_set(self.uset).search(result.xs[:, :2 * n], result.us, controller.window(), amb,
                                                          start_c=x[2 * n:], starts=1)
        return self.last

    def review(self, controller, x: np.ndarray, result: SolverResult, extend: bool = True):
        """The plan ``result`` from the planning state ``x`` checked against the set: ``(plan, solves, event)``;
        the plan is ``result`` itself, a re-solve with a shorter hold (event ``robust_cut``; when a cut's
        re-solve is not accepted, the last accepted plan with the hold already cut) or with a longer one
        (``robust_extend``); ``solves`` lists the re-solves made. Every plan returned is accepted."""
        limit = controller.lp.settings.limit_c + TOLERANCE_K
        motor, solves = self.search(controller, x, result), []
        if motor.peak_c > limit:
            for _ in range(MAX_CUTS):
                if not self._cut(controller, x, result, motor):
                    break
                cut = controller.solver.solve(x, controller.window(), WarmStart.from_result(result))
                solves.append(cut)
                if not controller._acceptable(cut, False):  # the last accepted plan stays; the hold is cut:
                    break                                   # the next re-solve plans it
                result, motor = cut, self.search(controller, x, cut)
                if motor.peak_c <= limit:
                    break
            log.info("t = %.1f s: hold cut to %.1f s for the set (worst motor %.2f °C)",
                     controller.k * controller.lp.settings.dt_s, controller.hold_s, motor.peak_c)
            return result, solves, "robust_cut"
        kept = controller.hold_knots
        if not extend or not self._extend(controller):
            return result, solves, None
        longer = controller.solver.solve(x, controller.window(), WarmStart.from_result(result))
        solves.append(longer)
        if controller._acceptable(longer, False) and self.search(controller, x, longer).peak_c <= limit:
            return longer, solves, "robust_extend"
        controller.hold_knots = kept
        self.search(controller, x, result)  # ``last``: the worst motor of the plan kept
        return result, solves, None

    def _cut(self, controller, x, result, motor: WorstMotor) -> bool:
        """Move the lowering earlier to where ``motor``'s winding crosses the limit (at least one hold step,
        never into the past); False when the hold cannot get shorter."""
        n = controller.lp.model.nu
        winding = self.worst.with_set(self.uset).replay(motor.theta, result.xs[:, :2 * n], result.us,
                                                        controller.window(), self._ambient(controller), x[2 * n:])
        over = np.flatnonzero(winding > controller.lp.settings.limit_c)
        end = controller.lift_knots + controller.hold_knots - controller.k  # the lowering's start in the window
        cross = int(over[0]) if over.size else end
        new = controller.hold_knots - max(self._step(controller), end - cross + 1)
        new = max(new, max(0, controller.k - controller.lift_knots))
        if new >= controller.hold_knots:
            return False
        controller.hold_knots = new
        return True

    def _extend(self, controller) -> bool:
        """One hold step more, up to the task's hold, while the lowering has not started."""
        task = int(round(controller.settings.scenario.hold_s / controller.lp.settings.dt_s))
        if controller.hold_knots >= task or controller.k >= controller.lift_knots + controller.hold_knots:
            return False
        controller.hold_knots = min(task, controller.hold_knots + self._step(controller))
        return True

    @staticmethod
    def _step(controller) -> int:
        return max(1, int(round(controller.settings.controller.hold_step_s / controller.lp.settings.dt_s)))

    @staticmethod
    def _ambient(controller) -> float:
        return controller.lp.model.ambient_c if controller.ambient_c is None else controller.ambient_c
