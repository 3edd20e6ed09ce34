"""The loop of designed experiments on the simulated robot (issue 25), in four steps per round:

1. diagnose the recordings (:func:`thermo_ddp.diagnose.thermal.diagnose_thermal`);
2. if anything is undetermined, design the experiment (:func:`thermo_ddp.tasks.experiment.design_experiment`);
3. run it on the simulated robot (a hidden truth of :mod:`thermo_ddp.testing.testbed.truths`, which the tool
   never reads: only its recording comes back);
4. diagnose again with the new recording (the next round's first step).

The loop ends when nothing is undetermined, when no experiment can be designed, or after ``rounds`` rounds.
"""
from __future__ import annotations

import dataclasses

import numpy as np

from .._config import require
from ..diagnose.thermal import diagnose_thermal
from ..tasks.experiment import ExperimentDesign, ExperimentSettings, design_experiment
from ..testing.testbed.truths import ThreeNodeTruth, run_programme


@dataclasses.dataclass(frozen=True)
class LoopRound:
    """One round: what the diagnosis named and left undetermined, the design, and the robot's true peak winding
    while it ran the experiment (None: no experiment ran)."""

    named: tuple[str, ...]
    undetermined: tuple[str, ...]
    design: ExperimentDesign
    true_peak_winding_c: float | None

    def to_dict(self) -> dict:
        return {"named": list(self.named), "undetermined": list(self.undetermined), "design": self.design.to_dict(),
                "true_peak_winding_c": self.true_peak_winding_c}


@dataclasses.dataclass(frozen=True)
class ExperimentLoop:
    """Result of :func:`close_the_loop`: the rounds and the final diagnosis (its JSON in :meth:`to_dict`)."""

    success: bool
    status: str
    message: str
    rounds: tuple[LoopRound, ...]
    final: object          # the last diagnosis (ThermalDiagnosis)

    def to_dict(self) -> dict:
        return {"success": self.success, "status": self.status, "message": self.message,
                "rounds": [r.to_dict() for r in self.rounds], "final": self.final.to_dict()}

    def report(self) -> str:
        lines = [f"experiment loop: {self.status}: {self.message}"]
        for k, r in enumerate(self.rounds, 1):
            peak = "" if r.true_peak_winding_c is None else f", robot's winding peak {r.true_peak_winding_c:.1f} °C"
            lines.append(f"  round {k}: named {', '.join(r.named) or 'nothing'}; undetermined "
                         f"{', '.join(r.undetermined) or 'nothing'}; design {r.design.status}{peak}")
        lines.append(f"  final: named {', '.join(self.final.missing_physics) or 'nothing'}")
        return "\n".join(lines)


def close_the_loop(recordings, truth: ThreeNodeTruth, *, rounds: int = 2, settings: ExperimentSettings | None = None,
                   seed: int = 0, noise_c: float = 0.05, sample_s: float = 2.0) -> ExperimentLoop:
    """Diagnose, design, run on the robot ``truth`` (measured with ``noise_c`` and ``sample_s``), diagnose again;
    at most ``rounds`` experiments (module docstring)."""
    require(isinstance(rounds, int) and rounds >= 1, "close_the_loop", "rounds", rounds, "expected an integer >= 1")
    settings = settings or ExperimentSettings()
    recs, done, rng = list(recordings), [], np.random.default_rng(seed)
    diagnosis = diagnose_thermal(recs)
    for k in range(rounds):
        design = design_experiment(recs, settings=settings, diagnosis=diagnosis)
        undetermined = tuple(dict.fromkeys(n["term"] for n in diagnosis.not_determinable))
        if not design.designed:
            done.append(LoopRound(tuple(diagnosis.missing_physics), undetermined, design, None))
            break
        run, temps = run_programme(truth, design.programme(), rng, f"designed_{k + 1}", noise_c=noise_c,
                                   sample_s=sample_s)
        done.append(LoopRound(tuple(diagnosis.missing_physics), undetermined, design, float(temps[:, 0].max())))
        recs.append(run)
        diagnosis = diagnose_thermal(recs)
    failed = [r.design for r in done if not r.design.success]
    status = "failed" if failed or not diagnosis.success else "ok"
    message = failed[0].message if failed else diagnosis.message
    return ExperimentLoop(status == "ok", status, message, tuple(done), diagnosis)
