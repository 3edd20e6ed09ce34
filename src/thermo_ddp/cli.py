"""The ``thermo-ddp`` command line: parse, validate, call, write atomically.

Exit status (docs/architecture.md): 0 the analysis reached a result (an infeasible plan is one);
1 it ran but failed (``success: false``; the JSON is still written); 2 bad input, one line on stderr,
before any work. Every output is checked before work (:class:`thermo_ddp.outputs.Outputs`) and
written only when the run ends.
"""
from __future__ import annotations

import argparse
import dataclasses
import json
import logging
import math
import sys
import warnings
from importlib import resources
from pathlib import Path
from typing import Callable

import numpy as np

from . import __version__
from ._cli_parsers import (JSON_STDOUT, Parser, cache_parser, demo_parser, design_parser, loop_parser, plan_parser,
                           recording_parser, split_global, sweep_parser)
from ._cli_parsers import top_parser as _top_parser
from ._logs import configure_logging
from ._reports import MAX_LINES, diagnosis_report, files_report, fit_lines, identification_report
from .errors import InputError, RunFailed
from .outputs import Outputs

log = logging.getLogger(__name__)

# Argument names holding input paths, and the output options by argument name: every output is
# refused when it is also an input (checked before any work, whatever the verb).
INPUT_ARGS = ("recordings", "model", "columns")
OUTPUT_ARGS = {"json": "--json", "plot": "--plot", "write_model": "--write-model", "experiment_csv": "--out"}
FIGURE_OPTIONS = ("--plot",)


@dataclasses.dataclass(frozen=True)
class Run:
    """What a command hands back: its ``report`` (printed) and its JSON-ready result (``data``: staged for
    ``--json`` when ``stage``; ``success: false`` in it gives exit 1)."""

    report: str
    data: dict | None = None
    stage: bool = True


def _demo(args, out: Outputs) -> Run:
    from .studies.demo import hold_demo
    return Run(hold_demo(args.payload_kg, args.hold_s).report())


def _plan(args, out: Outputs) -> Run:
    from .tasks.lift import plan_lift
    options = {"solver": args.solver, "careful_motion": args.careful_motion}
    if args.model:
        options["parameter_file"] = args.model
    plan = plan_lift(args.payload_kg, args.limit_c, args.hold_s, uncertainty=args.uncertainty, **options)
    out.figure("--plot", plan.plot)
    return Run(plan.report(), plan.to_dict())


def _compare(args, out: Outputs) -> Run:
    from ._figures import plot_comparison
    from .tasks.lift import compare_limits
    limits = tuple(args.limits_c) if args.limits_c else None
    comparison = compare_limits(args.payload_kg, limits, args.hold_s, solver=args.solver,
                                uncertainty=args.uncertainty)
    out.figure("--plot", lambda path: plot_comparison(comparison.plans, path))
    data = {"success": all(p.status != "failed" for p in comparison.plans), "payload_kg": args.payload_kg,
            "hold_s": args.hold_s, "rows": [r | {"status": p.status, "message": p.message}
                                            for r, p in zip(comparison.rows(), comparison.plans)]}
    return Run(comparison.table(), data)


def _loop(args, out: Outputs) -> Run:
    from .studies.loop import loop_files
    options = {"limits_c": tuple(args.limits_c), "columns": args.columns, "progress": _progress(args)}
    if args.hold_s is not None:
        options["hold_s"] = args.hold_s
    if args.no_oracle:  # else the settings' default: with the true parameters, except --short
        options["oracle"] = False
    if args.no_experiment or args.experiment_s is not None:
        options["experiment_s"] = None if args.no_experiment else args.experiment_s
    table = loop_files(args.out, short=args.short, **options)
    report = (Path(args.out) / "loop.txt").read_text().rstrip("\n")
    files = f"  files in {args.out}/: loop.txt, loop.json, loop.png, loop_summary.png, diagnosis.json, diagnosis.png, " \
            "experiment.json/.csv/.png, models/*.toml, recordings/*.csv"
    return Run(f"{report}\n{files}", {"success": table.get("success")}, stage=False)


def _design_experiment(args, out: Outputs) -> Run:
    from .tasks.experiment import ExperimentSettings, check_request, design_experiment, write_programme
    settings = ExperimentSettings(duration_s=args.duration_s, limit_c=args.limit_c, progress=_progress(args))
    params = check_request(args.model, settings)
    from .recordings import read_recordings
    recordings = read_recordings(args.recordings, args.columns)
    design = design_experiment(list(recordings.recordings), params, settings)
    if design.designed:
        out.figure("--out", lambda path: write_programme(design.programme(), path))
        out.figure("--plot", design.plot)
    return Run(design.report(), design.to_dict())


def _cache(args, out: Outputs) -> Run:
    from . import codegen
    lines = []
    if args.clear:
        lines.append(f"removed {codegen.clear_cache()} files from {codegen.cache_dir()}")
    if args.info or not args.clear:
        lines.append(codegen.cache_info().report())
    return Run("\n".join(lines))


def _identify(args, out: Outputs) -> Run:
    _check_physics_model(args)
    if args.physics == "mechanical":
        from .identify.mechanical import identify_mechanical_files
        result = identify_mechanical_files(args.recordings, columns=args.columns)
    else:
        from .identify.thermal_files import identify_thermal_files
        result = identify_thermal_files(args.recordings, parameters=args.model, columns=args.columns)
    _stage_model(out, result)
    return Run(identification_report(result), result)


def _diagnose(args, out: Outputs) -> Run:
    _check_physics_model(args)
    if args.each:
        return _diagnose_each(args, out)
    if args.physics == "mechanical":
        from .diagnose.mechanical import diagnose_mechanical_files
        result = diagnose_mechanical_files(args.recordings, plot=out.temporary("--plot"), columns=args.columns)
    else:
        from .diagnose.thermal import ThermalDiagnosisSettings, diagnose_thermal_files
        result = diagnose_thermal_files(args.recordings, plot=out.temporary("--plot"), parameters=args.model,
                                        columns=args.columns,
                                        settings=ThermalDiagnosisSettings(progress=_progress(args)))
    _stage_model(out, result)
    return Run(diagnosis_report(result), result)


def _diagnose_each(args, out: Outputs) -> Run:
    """``diagnose --each``: one diagnosis per recording (a fleet) as Dask tasks, and the fleet's table. Every
    recording and the parameter file are read and checked here first, before the cluster starts."""
    from .identify.thermal import load_joint_parameters
    from .recordings import read_recordings
    from .studies.engine import EngineSettings
    from .studies.fleet import diagnose_fleet
    for option in ("--plot", "--write-model"):
        if out.wanted(option):
            raise InputError(option, option, str(out.paths[option]), "one per recording: not with --each")
    engine = EngineSettings(scheduler=args.scheduler, workers=args.workers)
    options = {"columns": args.columns}
    if args.physics == "thermal" and args.model:
        load_joint_parameters(args.model)
        options["parameters"] = args.model
    for path in args.recordings:
        read_recordings([path], args.columns)
    fleet = diagnose_fleet(args.recordings, args.physics, engine, progress=_progress(args), **options)
    return Run(fleet.report(), fleet.to_dict())


def _validate(args, out: Outputs) -> Run:
    from .validate import validate_files
    result = validate_files(args.recordings, args.model, args.columns)
    if result.success:
        out.figure("--plot", result.plot)
    return Run(result.report(), result.to_dict())


def _sweep(args, out: Outputs) -> Run:
    from .studies.engine import EngineSettings
    from .studies.sweep import robustness_sweep
    result = robustness_sweep(args.runs, args.seed, args.short, EngineSettings(scheduler=args.scheduler,
                                                                               workers=args.workers),
                              progress=_progress(args), nominal_plan=args.nominal_plan)
    out.figure("--plot", result.plot)
    return Run(result.report(), result.to_dict())


def _progress(args) -> bool | None:
    """Progress bars: off with -q, else on a terminal only (None: tqdm's own test of stderr)."""
    return False if args.verbosity < 0 else None


def _check_physics_model(args) -> None:
    """A motor parameter file belongs to the thermal physics."""
    if args.physics == "mechanical" and (args.model or args.write_model):
        option = "--model" if args.model else "--write-model"
        raise InputError(option, option, args.model or args.write_model,
                         "a motor parameter file belongs to --physics thermal")


def _stage_model(out: Outputs, result: dict) -> None:
    """Stage the identified / improved parameter file (--write-model) when the run produced one."""
    from .model.parameters import dumps_parameters, parameters_from_dict
    if not out.wanted("--write-model"):
        return
    if result.get("parameter_file") is None:
        log.warning("no parameter file to write: the fit failed (%s)", result.get("message"))
        return
    out.text("--write-model", dumps_parameters(parameters_from_dict(result["parameter_file"], "--write-model")))


# --------------------------------------------------------------------------------------------
# Results: JSON-ready, never NaN, the exit status from ``success``
# --------------------------------------------------------------------------------------------
def _plain(value, where: str, bad: list[str]):
    """``value`` with numpy types as Python ones and non-finite numbers as None (their paths in ``bad``)."""
    if isinstance(value, dict):
        return {k: _plain(v, f"{where}.{k}", bad) for k, v in value.items()}
    if isinstance(value, (list, tuple, np.ndarray)):
        return [_plain(v, f"{where}[{i}]", bad) for i, v in enumerate(value)]
    if isinstance(value, np.generic):
        value = value.item()
    if isinstance(value, float) and not math.isfinite(value):
        bad.append(where)
        return None
    return value


def _result(data: dict, out: Outputs) -> dict:
    """``data`` JSON-ready and staged for ``--json`` (a file; stdout with ``--json -``); a result holding NaN
    or inf is not a result: it is marked failed (exit 1), never passed on."""
    bad: list[str] = []
    data = _plain(data, "", bad)
    if bad:
        log.warning("non-finite numbers in the result at %s", ", ".join(bad[:5]))
        data |= {"success": False, "status": "non_finite_result",
                 "message": f"the result holds non-finite numbers (first at {bad[0].lstrip('.')}); not trustworthy"}
    if out.wanted("--json"):
        out.json("--json", data)
    return data


def _outputs(args) -> Outputs:
    """Every output of ``args`` checked against every input (the packaged parameter files included: the
    default models) and each other, before any work; ``--json -`` is stdout, not a file."""
    inputs = sorted(Path(str(resources.files("thermo_ddp.models"))).glob("*.toml"))  # default models
    for name in INPUT_ARGS:
        value = getattr(args, name, None)
        inputs += list(value) if isinstance(value, (list, tuple)) else [value] if value else []
    wanted = {option: getattr(args, name, None) for name, option in OUTPUT_ARGS.items()}
    if wanted["--json"] == JSON_STDOUT:
        wanted["--json"] = None
    return Outputs.check(wanted, inputs, FIGURE_OPTIONS)


@dataclasses.dataclass(frozen=True)
class Command:
    summary: str  # one line for the top-level --help
    parser: Callable[[], Parser]
    run: Callable[[argparse.Namespace, Outputs], Run]


COMMANDS = {
    "plan": Command("plan the elbow lift under a winding-temperature limit",
                    lambda: plan_parser("plan", "plan the elbow lift under a winding-temperature limit"), _plan),
    "compare": Command("the lift planned under several winding limits, as a table",
                       lambda: plan_parser("compare", "the lift under several winding limits, as a table"), _compare),
    "demo": Command("static hold of a payload: torque, current, when the winding reaches its limits",
                    demo_parser, _demo),
    "identify": Command("fit a thermal or mechanical model to recordings (CSV)",
                        lambda: recording_parser("identify", "identify parameters from recordings", False), _identify),
    "diagnose": Command("find what a model misses in recordings, name the missing physics, refit",
                        lambda: recording_parser("diagnose", "locate model mismatch, name and add the missing "
                                                             "physics, refit and validate", True), _diagnose),
    "validate": Command("predict recordings with a parameter file as it is and report the error",
                        lambda: recording_parser("validate", "predict recordings with a parameter file as it is "
                                                             "(no refit) and report the error", True), _validate),
    "design-experiment": Command("plan the experiment that settles what recordings leave undetermined",
                                 design_parser, _design_experiment),
    "loop": Command("the whole chain on the simulated elbow: record, diagnose, improve, plan, run",
                    loop_parser, _loop),
    "sweep": Command("randomised closed-loop lifts on Dask: margins and holds", sweep_parser, _sweep),
    "cache": Command("the compiled-library cache: where, how big; --clear", cache_parser, _cache),
}


def top_parser() -> Parser:
    return _top_parser({name: c.summary for name, c in COMMANDS.items()}, __version__)


def main(argv: list[str] | None = None) -> int:
    verbosity, argv = split_global(sys.argv[1:] if argv is None else list(argv))
    ns = top_parser().parse_args(argv)
    command = COMMANDS[ns.command]
    args = command.parser().parse_intermixed_args(ns.args)
    args.verbosity = verbosity
    configure_logging(verbosity)
    out = Outputs()
    with warnings.catch_warnings(record=True) as caught:  # a refusal prints one line, nothing else
        warnings.simplefilter("default")
        try:
            _check_environment()
            out = _outputs(args)
            run = command.run(args, out)
            data = _result(run.data, out) if run.data is not None and run.stage else run.data
            written = _commit(out)
        except InputError as err:
            print(f"thermo-ddp: {err}", file=sys.stderr)
            return 2
        except RunFailed as err:
            print(f"thermo-ddp: {err}; nothing written, earlier files unchanged", file=sys.stderr)
            return 1
        except KeyboardInterrupt:
            print("thermo-ddp: interrupted; nothing written, earlier files unchanged", file=sys.stderr)
            return 130
        finally:
            out.discard()
    _print(run.report, data, written, getattr(args, "json", None) == JSON_STDOUT)
    for w in caught:  # the run went through: its warnings are for those who ask (-v)
        log.info("%s: %s (%s:%d)", w.category.__name__, w.message, w.filename, w.lineno)
    if written is None:
        return 1
    return 1 if data is not None and data.get("success") is False else 0


def _print(report: str, data: dict | None, written: dict[str, Path] | None, json_stdout: bool) -> None:
    """The report (on stderr when stdout carries the JSON), the files written, and the JSON for ``--json -``."""
    text = fit_lines(report, MAX_LINES - len(written or {}) - 1)
    if written:
        text += "\nfiles:\n" + files_report(written)
    print(text, file=sys.stderr if json_stdout else sys.stdout)
    if json_stdout and data is not None:
        print(json.dumps(data, indent=2, allow_nan=False))


def _check_environment() -> None:
    """The compiled-library cache settings ($THERMO_DDP_CACHE, $THERMO_DDP_CACHE_MAX_MB), before work."""
    from .codegen import cache_dir, cache_max_bytes
    folder = cache_dir()
    if folder.exists() and not folder.is_dir():
        raise InputError("environment", "THERMO_DDP_CACHE", str(folder), "is a file; expected a folder")
    cache_max_bytes()


def _commit(out: Outputs) -> dict[str, Path] | None:
    """Write the staged outputs (returned by option); None (one line on stderr, nothing replaced) when the
    system refuses."""
    try:
        written = out.commit()
    except OSError as err:
        print(f"thermo-ddp: cannot write the outputs ({err.strerror or err}); earlier files are unchanged",
              file=sys.stderr)
        return None
    return {option: path for option, path in out.paths.items() if path in written}


if __name__ == "__main__":
    sys.exit(main())
