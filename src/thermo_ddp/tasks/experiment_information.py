"""The information a designed experiment gives (:mod:`thermo_ddp.tasks.experiment`, steps 5 and 7).

From the weighted sensor sensitivities of the richest explanation (rows: samples; columns: its free values
relative to them, then each segment's initial offset), over the passive recordings and a design:

- :func:`information`: the Fisher information of the wanted values, the others and the offsets nuisances
  (Schur complement): its :func:`log_det` (D_s-criterion) picks the design among the starts;
- :func:`half_widths`: the predicted 95 % half-width of every value relative to it (Cramer-Rao bound: the
  linearised interval the diagnosis reports, before its inflation for autocorrelated residuals);
- :func:`undeterminable`: the values of the named terms and the targets that no start's design pins within
  +-50 % (the diagnosis's identifiability rule), with the passive fit's inflation: reported ``not_determinable``
  by the design before any run.
"""
from __future__ import annotations

import math

import numpy as np

from ..diagnose._thermal_terms import term_keys
from ..identify.fit_report import Z95
from .experiment_rivals import HEAT_TERMS, PERTURBATION, Explanations


def information(blocks: list[np.ndarray], wanted: np.ndarray) -> np.ndarray:
    """The Fisher information of the ``wanted`` parameters (a mask) from every segment's sensitivities, the other
    parameters and each segment's initial offset nuisances (Schur complement: D_s-optimality)."""
    q = blocks[0].shape[1] - 1
    j = np.zeros((sum(b.shape[0] for b in blocks), q + len(blocks)))
    row = 0
    for k, b in enumerate(blocks):
        j[row:row + b.shape[0], :q], j[row:row + b.shape[0], q + k] = b[:, :q], b[:, q]
        row += b.shape[0]
    keep = np.r_[wanted, np.zeros(len(blocks), bool)]
    m = j.T @ j
    a, b, c = m[np.ix_(keep, keep)], m[np.ix_(keep, ~keep)], m[np.ix_(~keep, ~keep)]
    return a - b @ np.linalg.pinv(c) @ b.T


def half_widths(blocks: list[np.ndarray]) -> np.ndarray:
    """Predicted 95 % half-width of every free value relative to it (the Cramer-Rao bound of the information from
    ``blocks``, each segment's initial offset a nuisance); a direction the information does not see: infinite."""
    info = information(blocks, np.ones(blocks[0].shape[1] - 1, bool))
    eig, vec = np.linalg.eigh(0.5 * (info + info.T))
    blind = eig <= 1e-12 * max(eig.max(), 1e-300)
    weights = vec ** 2
    variance = weights[:, ~blind] @ (1.0 / eig[~blind])
    return np.where((weights[:, blind] > 1e-6).any(axis=1), np.inf, Z95 * np.sqrt(variance))


def log_det(information: np.ndarray) -> float:
    """D-criterion: log det of the relative information (a floor keeps an unidentifiable direction finite)."""
    eig = np.linalg.eigvalsh(0.5 * (information + information.T))
    return float(np.sum(np.log(np.maximum(eig, 1e-9))))


def undeterminable(expl: Explanations, widths: list[np.ndarray], inflation: float = 1.0) -> tuple[dict, ...]:
    """The values of the named terms (the reference's) and of the targets that no design within the limits pins
    within +-:data:`PERTURBATION` (with the passive recordings): their smallest predicted 95 % half-width over the
    starts' designs (``widths``: :func:`half_widths` per design, in the richest explanation), times the
    diagnosis's ``inflation`` of its intervals for autocorrelated residuals (the passive fit's), is wider.  Said
    before any run.  A rival's other terms are not judged (the recordings may never name them)."""
    if not widths:
        return ()
    widths, richest, keys = inflation * np.min(widths, axis=0), expl.richest, list(expl.model.keys)
    judged = set(expl.reference.terms) | {t.term for t in expl.targets}
    out = []
    for term in (t for t in richest.terms if t in judged and t in (*HEAT_TERMS, "casing_node")):
        for key in term_keys(term, richest.terms):
            w = widths[keys.index(key)] if key in keys and richest.values.get(key, 0.0) > 0 else None
            if w is not None and w > PERTURBATION:
                half = "unbounded" if math.isinf(w) else f"+-{100 * w:.0f} %"
                out.append({"term": term, "key": key, "predicted_half_width": float(w) if math.isfinite(w) else None,
                            "reason": f"predicted 95 % half-width {half} of its value at best, over every start's "
                                      f"design within the limits and the duration (with the passive recordings)"})
    return tuple(out)
