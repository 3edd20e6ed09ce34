"""The DDP's PHR augmented Lagrangian for g <= 0: its terms, multiplier and penalty updates, and the local
infeasibility certificate (as ALTRO, Howell et al. IROS 2019; Nocedal & Wright section 17.4)."""
from __future__ import annotations

import dataclasses

import numpy as np


def terms(G, GN, lam, lamN, rho) -> float:
    """sum (max(0, lam + rho g)^2 - lam^2) / (2 rho) over the stage and terminal constraints."""
    return float((np.sum(np.maximum(0.0, lam + rho * G) ** 2 - lam ** 2)
                  + np.sum(np.maximum(0.0, lamN + rho * GN) ** 2 - lamN ** 2)) / (2 * rho))


def kkt_constraint(G, GN, lam, lamN, rho) -> float:
    """|max(g, -lam/rho)|_inf: zero exactly at a feasible, complementary point."""
    vals = [np.max(np.abs(np.maximum(G, -lam / rho)))] if G.size else [0.0]
    if GN.size:
        vals.append(np.max(np.abs(np.maximum(GN, -lamN / rho))))
    return float(max(vals))


def violation(G, GN) -> float:
    return max(float(np.max(G, initial=0.0)), float(np.max(GN, initial=0.0)))


@dataclasses.dataclass(frozen=True)
class Update:
    """One multiplier update: the penalty and violation there, and whether the inner loop before it had
    converged (only those count as evidence of infeasibility)."""

    penalty: float
    violation: float
    converged: bool


def update(settings, G, GN, lam, lamN, rho, viol_prev):
    """lam <- max(0, lam + rho g); rho x penalty_factor when the violation did not fall to a quarter of its
    previous value, / sqrt(penalty_factor) (not below penalty_init) when it fell below a hundredth of it: the
    penalty is only as large as feasibility needs. Returns (lam, lamN, rho, violation)."""
    viol = violation(G, GN)
    lam, lamN = np.maximum(0.0, lam + rho * G), np.maximum(0.0, lamN + rho * GN)
    if viol > 0.25 * viol_prev:
        rho = min(rho * settings.penalty_factor, settings.penalty_max)
    elif np.isfinite(viol_prev) and viol < 0.01 * viol_prev:  # (a warm start has no previous violation)
        rho = max(rho / settings.penalty_factor ** 0.5, settings.penalty_init)
    return lam, lamN, rho, viol


def stalled(settings, log: list[Update]) -> bool:
    """True when the last update followed a converged inner loop and, since a converged one at a penalty
    ``infeasibility_growth`` times smaller, the violation has not halved: more penalty no longer buys
    feasibility (a local infeasibility certificate)."""
    last = log[-1]
    earlier = [u.violation for u in log if u.converged and u.penalty * settings.infeasibility_growth <= last.penalty]
    return (last.converged and bool(earlier) and last.violation > 0.5 * earlier[-1]
            and last.violation > 10 * settings.constraint_tolerance)


def certificate(settings, rows, G, GN, log: list[Update]) -> dict:
    """The evidence of :func:`stalled`: penalties and violations at the converged inner loops' updates, and
    the constraints violated at the end (``rows``: the names of the rows of g and g_N)."""
    names = [n for names_, values in zip(rows, (G, GN)) if values.size
             for n, v in zip(names_, np.max(np.atleast_2d(values), axis=0)) if v > settings.constraint_tolerance]
    kept = [u for u in log if u.converged]
    return {"penalty": [u.penalty for u in kept], "violation": [u.violation for u in kept],
            "constraints": list(dict.fromkeys(names))}
