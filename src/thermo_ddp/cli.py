"""The ``thermo-ddp`` command line: parse, validate, call, write atomically.

Exit status (docs/architecture.md): 0 the analysis reached a result (an infeasible plan is one);
1 it ran but failed (``success: false``; the JSON is still written); 2 bad input, one line on stderr,
before any work. Every output is checked before work (:class:`thermo_ddp.outputs.Outputs`) and
written only when the run ends.
"""
from __future__ import annotations

import argparse
import json
import logging
import math
import sys
import warnings
from importlib import resources
from pathlib import Path

import numpy as np

from .errors import InputError, RunFailed
from .outputs import Outputs
from .tasks._common import DEFAULT_HOLD_S

log = logging.getLogger(__name__)

# Argument names holding input paths, and the output options by argument name: every output is
# refused when it is also an input (checked before any work, whatever the verb).
INPUT_ARGS = ("recordings", "model", "columns")
OUTPUT_ARGS = {"json": "--json", "plot": "--plot", "write_model": "--write-model"}
FIGURE_OPTIONS = ("--plot",)


def _demo(args, out: Outputs) -> int:
    from .studies.demo import hold_demo
    print(hold_demo(args.payload_kg, args.hold_s).report())
    return 0


def _plan(args, out: Outputs) -> int:
    from .tasks.lift import plan_lift
    options = {"solver": args.solver, "careful_motion": args.careful_motion}
    if args.model:
        options["parameter_file"] = args.model
    plan = plan_lift(args.payload_kg, args.limit_c, args.hold_s, **options)
    print(plan.report())
    out.figure("--plot", plan.plot)
    return _result(plan.to_dict(), out, stdout=False)


def _compare(args, out: Outputs) -> int:
    from .tasks.lift import compare_limits
    limits = tuple(args.limits_c) if args.limits_c else None
    print(compare_limits(args.payload_kg, limits, args.hold_s, solver=args.solver).table())
    return 0


def _loop(args, out: Outputs) -> int:
    from .studies.loop import loop_files
    options = {"limits_c": tuple(args.limits_c), "oracle": not args.no_oracle, "columns": args.columns}
    if args.hold_s is not None:
        options["hold_s"] = args.hold_s
    table = loop_files(args.out, short=args.short, **options)
    print((Path(args.out) / "loop.txt").read_text(), end="")
    print(f"outputs in {args.out}: loop.json, loop.png, loop_summary.png, diagnosis.json, models/, recordings/")
    return _exit_status(table)


def _cache(args, out: Outputs) -> int:
    from . import codegen
    if args.clear:
        print(f"removed {codegen.clear_cache()} files from {codegen.cache_dir()}")
    if args.info or not args.clear:
        print(codegen.cache_info().report())
    return 0


def _identify(args, out: Outputs) -> int:
    _check_physics_model(args)
    if args.physics == "mechanical":
        from .identify.mechanical import identify_mechanical_files
        result = identify_mechanical_files(args.recordings, columns=args.columns)
    else:
        from .identify.thermal_files import identify_thermal_files
        result = identify_thermal_files(args.recordings, parameters=args.model, columns=args.columns)
    _stage_model(out, result)
    return _result(result, out)


def _diagnose(args, out: Outputs) -> int:
    _check_physics_model(args)
    if args.each:
        return _diagnose_each(args, out)
    if args.physics == "mechanical":
        from .diagnose.mechanical import diagnose_mechanical_files
        result = diagnose_mechanical_files(args.recordings, plot=out.temporary("--plot"), columns=args.columns)
    else:
        from .diagnose.thermal import diagnose_thermal_files
        result = diagnose_thermal_files(args.recordings, plot=out.temporary("--plot"), parameters=args.model,
                                        columns=args.columns)
    _stage_model(out, result)
    return _result(result, out)


def _diagnose_each(args, out: Outputs) -> int:
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
    fleet = diagnose_fleet(args.recordings, args.physics, engine, **options)
    print(fleet.report())
    return _result(fleet.to_dict(), out, stdout=False)


def _validate(args, out: Outputs) -> int:
    from .validate import validate_files
    result = validate_files(args.recordings, args.model, args.columns)
    print(result.report())
    if result.success:
        out.figure("--plot", result.plot)
    return _result(result.to_dict(), out, stdout=False)


def _sweep(args, out: Outputs) -> int:
    from .studies.engine import EngineSettings
    from .studies.sweep import robustness_sweep
    result = robustness_sweep(args.runs, args.seed, args.short, EngineSettings(scheduler=args.scheduler,
                                                                               workers=args.workers))
    print(result.report())
    out.figure("--plot", result.plot)
    return _result(result.to_dict(), out, stdout=False)


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
def _exit_status(data: dict) -> int:
    """1 when the result says it ran but failed (``success: false``), else 0."""
    return 1 if data.get("success") is False else 0


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


def _result(data: dict, out: Outputs, stdout: bool = True) -> int:
    """Stage the result JSON for ``--json`` (or print it when ``stdout`` and no file was asked for);
    a result holding NaN or inf is not a result: it is marked failed (exit 1), never passed on."""
    bad: list[str] = []
    data = _plain(data, "", bad)
    if bad:
        log.warning("non-finite numbers in the result at %s", ", ".join(bad[:5]))
        data |= {"success": False, "status": "non_finite_result",
                 "message": f"the result holds non-finite numbers (first at {bad[0].lstrip('.')}); not trustworthy"}
    if out.wanted("--json"):
        out.json("--json", data)
    elif stdout:
        print(json.dumps(data, indent=2))
    return _exit_status(data)


def _outputs(args) -> Outputs:
    """Every output of ``args`` checked against every input (the packaged parameter files included: the
    default models) and each other, before any work."""
    inputs = sorted(Path(str(resources.files("thermo_ddp.models"))).glob("*.toml"))  # default models
    for name in INPUT_ARGS:
        value = getattr(args, name, None)
        inputs += list(value) if isinstance(value, (list, tuple)) else [value] if value else []
    wanted = {option: getattr(args, name, None) for name, option in OUTPUT_ARGS.items()}
    return Outputs.check(wanted, inputs, FIGURE_OPTIONS)


def _number(unit: str):
    """An argparse ``type``: a finite number (the unit named in the message)."""
    def parse(text: str) -> float:
        try:
            value = float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected a number in {unit}, got {text!r}") from None
        if not math.isfinite(value):
            raise argparse.ArgumentTypeError(f"expected a finite number in {unit}, got {text!r}")
        return value
    return parse


class _Parser(argparse.ArgumentParser):
    """argparse with a one-line error (the contract: exit 2 with a one-line message)."""

    def error(self, message: str):
        self.exit(2, f"{self.prog}: error: {message}\n")


def _recording_parser(name: str, description: str, plot: bool) -> _Parser:
    cmd = _Parser(prog=f"thermo-ddp {name}", description=description)
    cmd.add_argument("recordings", nargs="+", metavar="REC", help="CSV recordings (contract columns, or any "
                                                                  "columns with --columns); required")
    if name == "validate":
        cmd.add_argument("--model", metavar="TOML", required=True, help="parameter file to validate; required")
    else:
        cmd.add_argument("--physics", choices=("thermal", "mechanical"), default="thermal",
                         help="which physics to model (default %(default)s)")
        cmd.add_argument("--model", metavar="TOML", help="parameter file: fixed values and start values (default: "
                                                         "the packaged models/arm_left_4_joint.toml)")
        cmd.add_argument("--write-model", metavar="OUT.toml", help="write the identified / improved parameter "
                                                                   "file here (default: none)")
    cmd.add_argument("--columns", metavar="MAP.toml", help="column map: how the CSVs' own columns become the "
                                                           "recording contract (default: contract columns)")
    cmd.add_argument("--json", metavar="OUT", help="write the result JSON here (default: "
                                                   f"{'none' if name == 'validate' else 'stdout'})")
    if plot:
        cmd.add_argument("--plot", metavar="OUT.png", help=f"write the {name} figure here (default: none)")
    if name == "diagnose":
        cmd.add_argument("--each", action="store_true", help="flag: one diagnosis per recording (a fleet) as Dask "
                         "tasks, and a table of which recordings show which missing physics")
        _engine_arguments(cmd)
    return cmd


def _engine_arguments(cmd: _Parser) -> None:
    cmd.add_argument("--scheduler", metavar="ADDRESS", default=None,
                     help="Dask scheduler, e.g. tcp://127.0.0.1:8786 (default: a LocalCluster on this machine)")
    cmd.add_argument("--workers", type=int, default=2,
                     help="worker processes of the LocalCluster, count (default %(default)s; ignored with --scheduler)")


def _demo_parser() -> _Parser:
    demo = _Parser(prog="thermo-ddp demo", description="static hold of a payload by the elbow: torque, "
                                                       "current and winding heating")
    demo.add_argument("--payload-kg", type=_number("kg"), default=40.0, help="payload at the gripper, kg (default %(default)s)")
    demo.add_argument("--hold-s", type=_number("s"), default=DEFAULT_HOLD_S, help="duration of the hold, s (default %(default)s)")
    return demo


def _plan_parser(name: str, description: str) -> _Parser:
    cmd = _Parser(prog=f"thermo-ddp {name}", description=description)
    cmd.add_argument("--payload-kg", type=_number("kg"), default=40.0, help="payload at the gripper, kg (default %(default)s)")
    cmd.add_argument("--hold-s", type=_number("s"), default=DEFAULT_HOLD_S, help="requested hold at the goal, s (default %(default)s)")
    cmd.add_argument("--solver", choices=("ddp", "ipopt", "fatrop"), default="ddp",
                     help="solver of the transcribed problem (default %(default)s)")
    if name == "plan":
        cmd.add_argument("--limit-c", type=_number("°C"), default=None,
                         help="winding limit, °C (default: the model file's [limits] safety_cutoff_c, 84 for the elbow)")
        cmd.add_argument("--model", metavar="TOML", help="elbow parameter file (default: the packaged "
                                                         "models/arm_left_4_joint.toml)")
        cmd.add_argument("--json", metavar="OUT", help="write the plan JSON here (default: none)")
        cmd.add_argument("--plot", metavar="OUT.png", help="write the four-panel figure here (default: none)")
        cmd.add_argument("--careful-motion", action=argparse.BooleanOptionalAction, default=True,
                         help="flag, on by default (--no-careful-motion: off): one direction per phase, slow near the "
                              "joint stops, at rest at the end, an acceleration cost (LiftSettings.careful_motion)")
    else:
        cmd.add_argument("--limits-c", type=_number("°C"), nargs="+", default=None,
                         help="winding limits to compare, °C (default: the elbow file's safety_cutoff_c and "
                              "winding_max_c, 84 and 140)")
    return cmd


def _loop_parser() -> _Parser:
    cmd = _Parser(prog="thermo-ddp loop", description="recordings -> identification -> diagnosis -> improved "
                  "model -> plan -> closed loop, original vs improved model, on the simulated elbow")
    cmd.add_argument("--out", default="loop_out", help="output folder (default %(default)s)")
    cmd.add_argument("--short", action="store_true", help="flag: 30-minute experiments and a 45 s hold")
    cmd.add_argument("--hold-s", type=_number("s"), default=None,
                     help="requested hold at the goal, s (default: LoopSettings.hold_s; --short shortens it)")
    cmd.add_argument("--limits-c", type=_number("°C"), nargs="+", default=[84.0, 140.0],
                     help="winding limits, °C (default %(default)s)")
    cmd.add_argument("--no-oracle", action="store_true", help="flag: skip the run planned with the true parameters")
    cmd.add_argument("--columns", metavar="MAP.toml", help="column map: the robot logs its recordings in the map's own "
                                                           "column names and the chain reads them through it "
                                                           "(default: contract columns)")
    return cmd


def _sweep_parser() -> _Parser:
    cmd = _Parser(prog="thermo-ddp sweep", description="randomised closed-loop lifts (plant thermal values "
                  "+-25 %, friction +-30 %, sensor noise, start 30-60 °C) on Dask: a LocalCluster by default")
    cmd.add_argument("--runs", type=int, default=200, help="number of runs (default %(default)s)")
    cmd.add_argument("--short", action="store_true", help="flag: a 5 s hold instead of 15 s")
    cmd.add_argument("--seed", type=int, default=0, help="seed of the sweep; run i's seed is word i of its "
                                                         "stream (default %(default)s)")
    _engine_arguments(cmd)
    cmd.add_argument("--json", metavar="OUT", help="write the sweep JSON here (default: none)")
    cmd.add_argument("--plot", metavar="OUT.png", help="write the margin and hold histograms here (default: none)")
    return cmd


def _cache_parser() -> _Parser:
    from .codegen import DEFAULT_CACHE_MAX_MB
    cmd = _Parser(prog="thermo-ddp cache", description="the compiled-library cache: $THERMO_DDP_CACHE (default "
                  f"~/.cache/thermo_ddp), capped at $THERMO_DDP_CACHE_MAX_MB (default {DEFAULT_CACHE_MAX_MB:g} MB; "
                  "least recently used libraries are removed after a build)")
    cmd.add_argument("--clear", action="store_true", help="flag: remove the compiled libraries (nothing else)")
    cmd.add_argument("--info", action="store_true", help="flag: print the folder, libraries and size "
                                                         "(what the command does without flags)")
    return cmd


COMMANDS = {
    "loop": (_loop_parser, _loop),
    "plan": (lambda: _plan_parser("plan", "plan the elbow lift under a winding-temperature limit"), _plan),
    "compare": (lambda: _plan_parser("compare", "the lift under several winding limits, as a table"), _compare),
    "demo": (_demo_parser, _demo),
    "identify": (lambda: _recording_parser("identify", "identify parameters from recordings", False), _identify),
    "diagnose": (lambda: _recording_parser("diagnose", "locate model mismatch, name and add the missing "
                                                       "physics, refit and validate", True), _diagnose),
    "validate": (lambda: _recording_parser("validate", "predict recordings with a parameter file as it is "
                                                       "(no refit) and report the error", True), _validate),
    "cache": (_cache_parser, _cache),
    "sweep": (_sweep_parser, _sweep),
}


def top_parser() -> _Parser:
    top = _Parser(prog="thermo-ddp", description=__doc__)
    top.add_argument("-v", "--verbose", action="store_true", help="flag: log progress (INFO)")
    top.add_argument("command", choices=sorted(COMMANDS), help="required: one of %(choices)s")
    top.add_argument("args", nargs=argparse.REMAINDER, help="the command's arguments (see COMMAND --help)")
    return top


def main(argv: list[str] | None = None) -> int:
    ns = top_parser().parse_args(argv)
    make_parser, run = COMMANDS[ns.command]
    args = make_parser().parse_intermixed_args(ns.args)
    logging.basicConfig(level=logging.INFO if ns.verbose else logging.WARNING, format="%(name)s: %(message)s")
    out = Outputs()
    with warnings.catch_warnings(record=True) as caught:  # a refusal prints one line, nothing else
        warnings.simplefilter("default")
        try:
            _check_environment()
            out = _outputs(args)
            status = run(args, out)
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
    for w in caught:  # the run went through: its warnings are worth reading
        log.warning("%s: %s (%s:%d)", w.category.__name__, w.message, w.filename, w.lineno)
    return status if written else 1


def _check_environment() -> None:
    """The compiled-library cache settings ($THERMO_DDP_CACHE, $THERMO_DDP_CACHE_MAX_MB), before work."""
    from .codegen import cache_dir, cache_max_bytes
    folder = cache_dir()
    if folder.exists() and not folder.is_dir():
        raise InputError("environment", "THERMO_DDP_CACHE", str(folder), "is a file; expected a folder")
    cache_max_bytes()


def _commit(out: Outputs) -> bool:
    """Write the staged outputs; False (one line on stderr, nothing replaced) when the system refuses."""
    try:
        out.commit()
    except OSError as err:
        print(f"thermo-ddp: cannot write the outputs ({err.strerror or err}); earlier files are unchanged",
              file=sys.stderr)
        return False
    return True


if __name__ == "__main__":
    sys.exit(main())
