"""The DDP solver's accepted iterate and its backtracking line search on the merit phi = cost + AL terms + mu |gaps|_1
(the method: solvers/ddp.py's docstring)."""
from __future__ import annotations

import dataclasses

import numpy as np

from . import _augmented_lagrangian as al
from .result import constraint_violation

# ``DDPSettings.retry_crossed_rows``: a line search is cut short after this many rejected trials that crossed a kink
# outside the local model within the first CROSSED_REACH of their way (measured best of 1-3 trials and reaches
# 0.02-0.3 on the lift's longest-hold searches; benchmarks/README.md, passes7).
CROSSED_TRIALS, CROSSED_REACH = 1, 0.1


@dataclasses.dataclass
class Iterate:
    """The accepted trajectory and its evaluations (the DDP solver's workspace, never returned)."""

    X: np.ndarray
    U: np.ndarray
    J: float
    G: np.ndarray
    GN: np.ndarray
    C: np.ndarray
    terms: float | None = None      # its augmented-Lagrangian terms at the current multipliers (None: not known)
    kkt_c: float | None = None      # its |max(g, -lam/rho)|_inf at the current multipliers (None: not known)
    violation: float | None = None  # its result.constraint_violation (None: not known)

    def al_terms(self, lam, lamN, rho) -> float:
        """The augmented-Lagrangian terms at (lam, lamN, rho), computed once per multiplier update."""
        if self.terms is None:
            self.terms = al.terms(self.G, self.GN, lam, lamN, rho)
        return self.terms

    def kkt_constraint(self, lam, lamN, rho) -> float:
        """al.kkt_constraint at (lam, lamN, rho), computed once per multiplier update."""
        if self.kkt_c is None:
            self.kkt_c = al.kkt_constraint(self.G, self.GN, lam, lamN, rho)
        return self.kkt_c

    def new_multipliers(self) -> None:
        """The multipliers or penalties changed: forget the figures that depend on them."""
        self.terms = self.kkt_c = None

    def max_violation(self, u_lb, u_ub) -> float:
        """result.constraint_violation of this iterate (the control bounds ``u_lb``, ``u_ub``), computed once."""
        if self.violation is None:
            self.violation = constraint_violation(self.G, self.GN, self.C, self.U, u_lb, u_ub)
        return self.violation


def backtrack(settings, backend, it_, P, policy, d1, d2, lam, lamN, rho, mu_gap, recent=-np.inf, cut=0, start=1.0,
              floor=None):
    """Backtracking on the merit from step ``start``; returns (alpha, accepted iterate or None, gap penalty,
    forward passes, the rows the rejected trials crossed early outside the model (al.crossed; None: none)).
    ``recent``: the largest merit of the last iterates at these multipliers (nonmonotone reference, used
    on gap-free iterates); ``cut`` > 0: stop after that many rejected trials once such rows were found; no
    trial below ``floor``."""
    s, be = settings, backend
    gap_l1 = float(np.abs(it_.C).sum())
    if gap_l1 > 0:
        need = (d1 + 0.5 * max(d2, 0.0)) / (0.9 * gap_l1)
        mu_gap = max(mu_gap, need + 1e-8)
    merit0 = it_.J + it_.al_terms(lam, lamN, rho) + mu_gap * gap_l1
    noise = 1e-13 * (1.0 + abs(merit0))
    reference = max(merit0, recent) if gap_l1 == 0 else merit0
    alpha, tries, crossed = start, 0, None
    while alpha >= (s.line_search_min_step if floor is None else floor):
        tries += 1
        X, U, J, G, GN = be.forward(it_.X, it_.U, P, policy, it_.C, alpha)
        if np.isfinite(J) and np.isfinite(X).all():
            terms = al.terms(G, GN, lam, lamN, rho)
            merit = J + terms + mu_gap * (1 - alpha) * gap_l1
            model = alpha * d1 + 0.5 * alpha ** 2 * d2 - alpha * mu_gap * gap_l1
            if merit - reference <= s.armijo * min(model, 0.0) + noise:
                C = np.zeros_like(it_.C) if alpha == 1.0 else (1 - alpha) * it_.C
                return alpha, Iterate(X, U, J, G, GN, C, terms), mu_gap, tries, crossed
            if cut:
                rows = al.crossed(it_.G, it_.GN, G, GN, lam, lamN, rho, s.active_margin, CROSSED_REACH)
                if rows[0].any() or rows[1].any():
                    crossed = rows if crossed is None else (crossed[0] | rows[0], crossed[1] | rows[1])
        alpha *= s.line_search_factor
        if tries == cut and crossed is not None:
            break
    return alpha, None, mu_gap, tries, crossed
