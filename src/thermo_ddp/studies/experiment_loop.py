"""The loop of designed experiments on the simulated robot (issue 25), in four steps per round:

1. diagnose the recordings (:func:`thermo_ddp.diagnose.thermal.diagnose_thermal`);
2. if anything is undetermined, design the experiment (:func:`thermo_ddp.tasks.experiment.design_experiment`);
3. run it on the simulated robot (a hidden truth of :mod:`thermo_ddp.testing.testbed.truths`, which the tool
   never reads: only its recording comes back);
4. diagnose again with the new recording (the next round's first step).

The loop ends when nothing is undetermined, when no experiment can be designed, or after ``rounds`` rounds.
With ``shared``, the rounds share one duration (a sequential design at the duration of one experiment): each
round is designed for an equal share of what is left, from the diagnosis of everything run so far (what it
narrowed: a casing node's resistance, which sets the winding guard; what is still open), or for all that is left
when nothing can be designed in its share.

:func:`experiment_stage` is the same round on the elbow robot of ``thermo-ddp loop``
(:mod:`thermo_ddp.studies.loop`): the testbed runs the programme
(:func:`thermo_ddp.testing.testbed.programmed`) and the robot's log joins the recordings.
"""
from __future__ import annotations

import dataclasses
from typing import Callable

import numpy as np

from .._config import require
from ..diagnose.thermal import ThermalDiagnosis, ThermalDiagnosisSettings, diagnose_thermal
from ..tasks.experiment import ExperimentDesign, ExperimentSettings, design_experiment, winding_rise_k_per_w
from ..testing.testbed import PlantParameters, SimulatedRecording, programmed
from ..testing.testbed.truths import ThreeNodeTruth, run_programme


def undetermined(diagnosis: ThermalDiagnosis) -> tuple[str, ...]:
    """The items a diagnosis leaves undetermined, each once."""
    return tuple(dict.fromkeys(n["term"] for n in diagnosis.not_determinable))


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
                   seed: int = 0, noise_c: float = 0.05, sample_s: float = 2.0,
                   diagnosis: ThermalDiagnosis | None = None, shared: bool = False) -> ExperimentLoop:
    """Diagnose, design, run on the robot ``truth`` (measured with ``noise_c`` and ``sample_s``), diagnose again;
    at most ``rounds`` experiments (module docstring), each planned for what the previous left open.
    ``shared``: ``settings.duration_s`` is the total the rounds share (a sequential design at the duration of one
    experiment: each round an equal share of what is left), else each round's.  ``diagnosis``: that of ``recordings`` when known."""
    require(isinstance(rounds, int) and rounds >= 1, "close_the_loop", "rounds", rounds, "expected an integer >= 1")
    settings = settings or ExperimentSettings()
    recs, done, rng = list(recordings), [], np.random.default_rng(seed)
    diagnosis = diagnosis or diagnose_thermal(recs)
    # every round guards the winding at least as the first did: a later fit's narrower interval of the winding
    # node may be biased (case 90019: 92.9 °C under an 84 °C limit with the second round's own guard)
    floor = max(winding_rise_k_per_w(diagnosis), settings.winding_rise_k_per_w) if diagnosis.final_fit else 0.0
    settings = dataclasses.replace(settings, winding_rise_k_per_w=floor)
    left_s = settings.duration_s
    for k in range(rounds):
        design = _round_design(recs, settings, diagnosis, left_s, rounds - k if shared else 1)
        if not design.designed:
            done.append(LoopRound(tuple(diagnosis.missing_physics), undetermined(diagnosis), design, None))
            break
        run, temps = run_programme(truth, design.programme(), rng, f"designed_{k + 1}", noise_c=noise_c,
                                   sample_s=sample_s)
        done.append(LoopRound(tuple(diagnosis.missing_physics), undetermined(diagnosis), design,
                              float(temps[:, 0].max())))
        recs.append(run)
        diagnosis = diagnose_thermal(recs)
        left_s -= design.duration_s if shared else 0.0
        if left_s < settings.dt_s:
            break
    failed = [r.design for r in done if not r.design.success]
    status = "failed" if failed or not diagnosis.success else "ok"
    message = failed[0].message if failed else diagnosis.message
    return ExperimentLoop(status == "ok", status, message, tuple(done), diagnosis)


def _round_design(recs, settings: ExperimentSettings, diagnosis, left_s: float, rounds_left: int) -> ExperimentDesign:
    """The round's design in its share of what is left; when nothing can be designed in that share (explanations
    no shorter programme moves a sensor noise apart), in all that is left (the last round then)."""
    share = dataclasses.replace(settings, duration_s=left_s / rounds_left)
    design = design_experiment(recs, settings=share, diagnosis=diagnosis)
    if design.designed or rounds_left == 1 or design.status != "not_designable":
        return design
    return design_experiment(recs, settings=dataclasses.replace(settings, duration_s=left_s), diagnosis=diagnosis)


# ----------------------------------------------------------------------------- the stage of ``thermo-ddp loop``
@dataclasses.dataclass(frozen=True)
class ExperimentStage:
    """The experiment stage of ``thermo-ddp loop``: the diagnosis of the report's recordings (``before``), the
    design, the robot's run of it (None: nothing ran) and the diagnosis with its log (``after``; ``before``
    when nothing ran)."""

    before: ThermalDiagnosis
    after: ThermalDiagnosis
    design: ExperimentDesign
    run: SimulatedRecording | None = None

    @property
    def true_peak_winding_c(self) -> float | None:
        """The robot's true winding peak while it ran the experiment (the testbed's hidden truth)."""
        return None if self.run is None else float(self.run.truth.winding_c.max())

    def to_dict(self) -> dict:
        return {"undetermined_before": list(undetermined(self.before)), "design": self.design.to_dict(),
                "ran": self.run is not None, "duration_s": self.design.duration_s,
                "true_peak_winding_c": self.true_peak_winding_c,
                "named_after": list(self.after.missing_physics), "undetermined_after": list(undetermined(self.after))}

    def report_lines(self) -> list[str]:
        """What the stage did: the design, the robot's run, what the diagnosis says with it (one line: no run)."""
        gaps = ", ".join(undetermined(self.before)) or "nothing"
        d = self.design
        if self.run is None:
            return [f"experiment: undetermined {gaps}; {d.status}: {d.message}"]
        return [f"experiment: undetermined {gaps}; designed {d.duration_s / 60:.0f} min for {', '.join(d.targets)} "
                f"(current up to {d.current_a.max():.2f} A, speed up to {d.speed_rad_s.max():.2f} rad/s)",
                f"  the robot ran it: true winding peak {self.true_peak_winding_c:.1f} °C (the design's bound "
                f"{d.peak_winding_c:.1f} °C, limit {d.limit_c:g} °C)",
                f"  diagnosed again with it: missing physics {', '.join(self.after.missing_physics) or 'none'}; "
                f"undetermined {', '.join(undetermined(self.after)) or 'nothing'}"]


def experiment_stage(robot: PlantParameters, sources: list, diagnosis: ThermalDiagnosis,
                     settings: ExperimentSettings, log_run: Callable[[SimulatedRecording], object],
                     seed: int = 0) -> tuple[ExperimentStage, list]:
    """Steps 2-4 on the testbed elbow ``robot`` after the diagnosis of ``sources``: design (if anything is
    undetermined), run the programme on the robot, log it (``log_run`` returns what the diagnosis reads: a file),
    diagnose again.  Returns the stage and the sources with the robot's log."""
    design = design_experiment(sources, settings=settings, diagnosis=diagnosis)
    if not design.designed:
        return ExperimentStage(diagnosis, diagnosis, design), list(sources)
    run = programmed(design.programme(), name="designed_experiment", params=robot, seed=seed)
    sources = [*sources, log_run(run)]
    after = diagnose_thermal(sources, settings=ThermalDiagnosisSettings(progress=settings.progress))
    return ExperimentStage(diagnosis, after, design, run), sources
