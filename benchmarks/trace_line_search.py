"""Why DDP's line search spends extra forward passes: a trace of plan_lift's longest-hold search (issue 23).

Every forward pass of every line search is recorded (the backend's ``forward`` is wrapped for the duration of one
line search; nothing in the solver changes). For each rejected trial: its step alpha, whether the iterate still
had dynamics gaps, and the constraint rows the trial found active (lam + rho g > 0) that the local model at the
iterate did not contain (inactive there and not lam > 0 within ``active_margin`` of g = 0): the kinks the step
crossed unmodelled. Printed per line search with more than one trial, then a summary. With the lift's
``retry_crossed_rows`` a search cut short after its first trial is followed by the search of the new direction.

    python benchmarks/trace_line_search.py [--payload-kg 40] [--limit-c 140]
"""
from __future__ import annotations

import argparse
import collections

import numpy as np

from thermo_ddp.solvers import ddp
from thermo_ddp.tasks.lift import plan_lift
from thermo_ddp.tasks.limits import DEFAULT_HOLD_S


def _unmodelled(solver, it_, G, lam, rho):
    """The (knot, row) mask of rows active at a trial's G and outside the local model at the iterate."""
    rg = rho[: lam.shape[1]]
    modelled = (lam + rg * it_.G > 0) | ((lam > 0) & (it_.G > -solver.settings.active_margin))
    return (lam + rg * G > 0) & ~modelled


def traced(searches: list):
    """A replacement of DDPSolver._line_search that records each trial of each search in ``searches``."""
    original = ddp.DDPSolver._line_search

    def line_search(self, it_, P, policy, d1, d2, lam, lamN, rho, mu_gap, *args, **kwargs):
        forward, trials = self.backend.forward, []

        def recorded(X, U, P_, pol, C, alpha):
            out = forward(X, U, P_, pol, C, alpha)
            crossed = _unmodelled(self, it_, out[3], lam, rho)
            names = sorted({self._rows[0][j] for j in np.flatnonzero(crossed.any(0))})
            trials.append({"alpha": alpha, "rows": int(crossed.sum()), "names": names,
                           "knots": np.flatnonzero(crossed.any(1)).tolist(), "lam_pos": int((lam[crossed] > 0).sum()),
                           "gaps": bool(it_.C.any())})
            return out

        self.backend.forward = recorded
        try:
            result = original(self, it_, P, policy, d1, d2, lam, lamN, rho, mu_gap, *args, **kwargs)
        finally:
            del self.backend.forward
        searches.append((result[0], result[1] is not None, trials))
        return result
    return original, line_search


def summary(searches) -> dict:
    rejected = [t for alpha, ok, trials in searches for t in (trials[:-1] if ok else trials)]
    extra = collections.Counter(len(trials) - ok for _, ok, trials in searches if len(trials) - ok)
    return {"line_searches": len(searches), "forward_passes": sum(len(t) for *_, t in searches),
            "rejected": len(rejected), "rejected_crossing_unmodelled_rows": sum(t["rows"] > 0 for t in rejected),
            "rejected_with_gaps": sum(t["gaps"] for t in rejected),
            "rejected_crossing_rows_with_lam_positive": sum(t["lam_pos"] > 0 for t in rejected),
            "rejected_at_full_step": sum(t["alpha"] == 1.0 for t in rejected),
            "searches_by_rejections": dict(sorted(extra.items()))}


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--payload-kg", type=float, default=40.0)
    ap.add_argument("--limit-c", type=float, default=140.0)
    args = ap.parse_args()
    searches = []
    original, ddp.DDPSolver._line_search = traced(searches)
    try:
        plan = plan_lift(args.payload_kg, args.limit_c, DEFAULT_HOLD_S)
    finally:
        ddp.DDPSolver._line_search = original
    print(f"{args.payload_kg:g} kg {args.limit_c:g} °C: hold {plan.achieved_hold_s:.1f} s, work {plan.solver['work']}")
    for i, (alpha, ok, trials) in enumerate(searches):
        if len(trials) > 1 or not ok:
            shown = [f"a={t['alpha']:.3g}: {t['rows']} rows {','.join(t['names'])} knots {t['knots'][:4]}"
                     f"{' lam>0:%d' % t['lam_pos'] if t['lam_pos'] else ''}{' (gaps)' if t['gaps'] else ''}"
                     for t in (trials[:-1] if ok else trials)]
            outcome = f"took {alpha:.3g}" if ok else "no step (failed, or cut short for a new direction)"
            print(f"search {i}: {outcome}; rejected " + "; ".join(shown))
    print(summary(searches))


if __name__ == "__main__":
    main()
