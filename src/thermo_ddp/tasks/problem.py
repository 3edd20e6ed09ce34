"""A transcribed task (:class:`TaskProblem`) and its initial guess.

A task problem's per-knot parameters start with the joints' reference angles ``q_ref`` (one column per
joint, in the model's order)."""
from __future__ import annotations

import dataclasses

import numpy as np

from ..model.actuated import ActuatedArm
from ..ocp import OptimalControlProblem
from ..solvers import WarmStart


@dataclasses.dataclass(frozen=True)
class TaskProblem:
    """A transcribed task: the OCP and its data (initial state, per-knot parameters named by
    ``problem.parameters``, with a ``q_ref_rad`` block, and the time grid).

    ``box_names``: the name of each control's current box (``current_peak``...)."""

    model: ActuatedArm
    problem: OptimalControlProblem
    x0: np.ndarray
    params: np.ndarray
    time_s: np.ndarray
    box_names: tuple[str, ...]


def initial_guess(tp: TaskProblem) -> WarmStart:
    """States on the reference (angles, and speeds its time derivative) at the initial temperatures, currents
    from static gravity compensation.

    The speeds matter with careful motion: at rest on a moving reference, DDP started light lifts far
    from the one-way and stop-approach constraints' feasible side (20 kg, 84 °C, 40 s hold: a false
    'infeasible' after 80 iterations; with the reference's speeds: converged in 18)."""
    q_ref = tp.params[:, tp.problem.parameters.slice("q_ref_rad")]
    xs = np.tile(tp.x0, (q_ref.shape[0], 1))
    xs[:, [tp.model.index(j, "q_rad") for j in tp.model.joints]] = q_ref
    xs[:, [tp.model.index(j, "v_rad_s") for j in tp.model.joints]] = np.gradient(q_ref, tp.time_s, axis=0)
    us = tp.model.static_current_a(q_ref[:-1])
    return WarmStart(xs, us)

