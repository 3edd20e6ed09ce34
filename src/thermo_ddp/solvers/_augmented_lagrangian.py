"""The DDP's PHR augmented Lagrangian for g <= 0 with a penalty per constraint row: its terms, multiplier and
penalty updates, and the local infeasibility certificate (as ALTRO, Howell et al. IROS 2019; Nocedal & Wright
section 17.4; per-constraint penalties as in Conn, Gould & Toint's LANCELOT, 1992).

``rho`` is one vector: the penalties of the rows of the stage g (shared by every knot), then of g_N. Rows in
different units (degC, V, rad, rad/s) each get the penalty their own violation needs."""
from __future__ import annotations

import dataclasses

import numpy as np


def split(rho, G):
    """(penalties of the stage rows, of the terminal rows)."""
    ng = G.shape[-1] if G.ndim == 2 else 0
    return rho[:ng], rho[ng:]


def phr(g, lam, rho, maximum=np.maximum):
    """Each row's (max(0, lam + rho g)^2 - lam^2) / (2 rho); ``maximum``: ``casadi.fmax`` for symbols."""
    return (maximum(0.0, lam + rho * g) ** 2 - lam ** 2) / (2 * rho)


def terms(G, GN, lam, lamN, rho) -> float:
    """The sum of :func:`phr` over the stage and terminal constraints."""
    rg, rN = split(rho, G)
    return float(phr(G, lam, rg).sum() + phr(GN, lamN, rN).sum())


def multipliers(G, GN, lam, lamN, rho):
    """The first-order multiplier estimates max(0, lam + rho g)."""
    rg, rN = split(rho, G)
    return np.maximum(0.0, lam + rg * G), np.maximum(0.0, lamN + rN * GN)


def kkt_constraint(G, GN, lam, lamN, rho) -> float:
    """|max(g, -lam/rho)|_inf: zero exactly at a feasible, complementary point."""
    rg, rN = split(rho, G)
    return float(max(np.abs(np.maximum(G, -lam / rg)).max(initial=0.0),
                     np.abs(np.maximum(GN, -lamN / rN)).max(initial=0.0)))


def crossed(G, GN, G_trial, GN_trial, lam, lamN, rho, margin: float, reach: float = 1.0):
    """The rows (stage (N, ng), terminal (ngN)) active at a trial point (lam + rho g > 0) but not in the local
    model at the iterate (there inactive, and not lam > 0 within ``margin`` of g = 0), whose kink g = -lam/rho
    lies within the first ``reach`` of the way from the iterate to the trial (g linear in between): the kinks a
    step crossed early that its model did not have."""
    rg, rN = split(rho, G)

    def rows(g, g_trial, lm, r):
        early = (-lm / r - g) <= reach * (g_trial - g)
        return (lm + r * g_trial > 0) & ~((lm + r * g > 0) | ((lm > 0) & (g > -margin))) & early
    return rows(G, G_trial, lam, rg), rows(GN, GN_trial, lamN, rN)


def flagged(lam, flags):
    """The multipliers as the backward pass takes them: a row of ``flags`` is modelled as active whatever its
    value, marked by the sign, -max(lam, tiny) (_riccati.knot_model). Never for the gradient pass."""
    return lam if flags is None else np.where(flags, -np.maximum(lam, np.finfo(float).tiny), lam)


def row_violation(G, GN) -> np.ndarray:
    """The largest violation max(g, 0) of every row (stage rows over the knots, then terminal rows)."""
    stage = np.max(np.maximum(G, 0.0), axis=0) if G.size else np.zeros(G.shape[-1] if G.ndim == 2 else 0)
    return np.concatenate([stage, np.maximum(GN, 0.0)])


def violation(G, GN) -> float:
    return float(np.max(row_violation(G, GN), initial=0.0))


@dataclasses.dataclass(frozen=True)
class Update:
    """One multiplier update: the largest penalty of the violated rows (of all rows when none is) and the
    largest violation there, whether the inner loop before it had converged (only those count as evidence of
    infeasibility), and every row's penalty and violation (the evidence is per row: rows in degC, V and rad do
    not compare)."""

    penalty: float
    violation: float
    converged: bool
    row_penalties: np.ndarray | None = None
    row_violations: np.ndarray | None = None

    @staticmethod
    def at(settings, G, GN, rho, converged: bool) -> "Update":
        rows = row_violation(G, GN)
        violated = rows > settings.constraint_tolerance
        penalty = np.max(rho[violated]) if violated.any() else np.max(rho, initial=0.0)
        return Update(float(penalty), float(np.max(rows, initial=0.0)), converged, np.array(rho, float), rows)


def update(settings, G, GN, lam, lamN, rho, viol_prev):
    """lam <- max(0, lam + rho g); per row, rho x penalty_factor where the row is violated and its violation did
    not fall to a quarter of its previous value, / sqrt(penalty_factor) (not below penalty_init) where it fell
    below a hundredth of it: each row's penalty only as large as its feasibility needs. ``viol_prev`` (per row;
    inf: no previous update). Returns (lam, lamN, rho, the rows' violations)."""
    viol = row_violation(G, GN)
    lam, lamN = multipliers(G, GN, lam, lamN, rho)
    grow = (viol > 0.25 * viol_prev) & (viol > settings.constraint_tolerance)
    shrink = np.isfinite(viol_prev) & (viol < 0.01 * viol_prev)
    rho = np.where(grow, np.minimum(rho * settings.penalty_factor, settings.penalty_max), rho)
    rho = np.where(shrink, np.maximum(rho / settings.penalty_factor ** 0.5, settings.penalty_init), rho)
    return lam, lamN, rho, viol


def stalled(settings, log: list[Update]) -> bool:
    """True when the last update followed a converged inner loop and, since converged ones at penalties
    ``infeasibility_growth`` times smaller, neither the largest violation nor some row's own violation (at that
    row's own penalty) has halved: more penalty no longer buys feasibility (a local infeasibility certificate).
    Both are asked, measured on lift probes that IPOPT and DDP solve feasible (benchmarks/README.md): the largest
    violation alone certified one (37.5 kg, 73.7 °C) where a hold-band row in rad, at its first penalty, stood
    above the winding row whose penalty grew; a row alone certified another (51.4 kg, 102.3 °C) whose largest
    violation fell 0.13 -> 4.5e-5 while a hold-band row's, tiny, did not halve."""
    last, growth = log[-1], settings.infeasibility_growth
    if not (last.converged and last.violation > 10 * settings.constraint_tolerance):
        return False
    earlier = [u.violation for u in log if u.converged and u.penalty * growth <= last.penalty]
    if not (earlier and last.violation > 0.5 * earlier[-1]):
        return False
    if last.row_penalties is None:  # scalar evidence only
        return True
    reference = np.full(last.row_violations.shape, np.inf)
    for u in log[:-1]:
        if u.converged and u.row_penalties is not None:
            grown = u.row_penalties * growth <= last.row_penalties
            reference = np.where(grown, u.row_violations, reference)
    stuck = (last.row_violations > 0.5 * reference) & (last.row_violations > 10 * settings.constraint_tolerance)
    return bool(np.any(stuck & np.isfinite(reference)))


def certificate(settings, rows, G, GN, log: list[Update]) -> dict:
    """The evidence of :func:`stalled`: penalties and violations at the converged inner loops' updates, and
    the constraints violated at the end (``rows``: the names of the rows of g and g_N)."""
    names = [n for n, v in zip(rows[0] + rows[1], row_violation(G, GN)) if v > settings.constraint_tolerance]
    kept = [u for u in log if u.converged]
    return {"penalty": [u.penalty for u in kept], "violation": [u.violation for u in kept],
            "constraints": list(dict.fromkeys(names))}
