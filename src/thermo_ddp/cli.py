"""The ``thermo-ddp`` command line. Bad input: one line on stderr and exit status 2."""
from __future__ import annotations

import argparse
import json
import logging
import sys
from pathlib import Path

from .errors import InputError
from .tasks._common import DEFAULT_HOLD_S


def _demo(args) -> int:
    from .studies.demo import hold_demo
    print(hold_demo(args.payload_kg, args.hold_s).report())
    return 0


def _plan(args) -> int:
    from .tasks.lift import plan_lift
    options = {"solver": args.solver}
    if args.model:
        options["parameter_file"] = args.model
    plan = plan_lift(args.payload_kg, args.limit_c, args.hold_s, **options)
    print(plan.report())
    if args.json:
        _write_json(plan.to_dict(), args.json)
    if args.plot:
        plan.plot(args.plot)
    return 0


def _compare(args) -> int:
    from .tasks.lift import compare_limits
    limits = tuple(args.limits_c) if args.limits_c else None
    print(compare_limits(args.payload_kg, limits, args.hold_s, solver=args.solver).table())
    return 0


def _loop(args) -> int:
    from .studies.loop import loop_files
    options = {"limits_c": tuple(args.limits_c), "oracle": not args.no_oracle}
    if args.hold_s is not None:
        options["hold_s"] = args.hold_s
    loop_files(args.out, short=args.short, **options)
    print((Path(args.out) / "loop.txt").read_text(), end="")
    print(f"outputs in {args.out}: loop.json, loop.png, loop_summary.png, diagnosis.json, models/, recordings/")
    return 0


def _sweep(args) -> int:
    from .outputs import Outputs
    from .studies.engine import EngineSettings
    from .studies.sweep import MAX_RUNS, robustness_sweep
    if not 1 <= args.runs <= MAX_RUNS:
        raise InputError("--runs", "--runs", args.runs, f"must be in [1, {MAX_RUNS}]")
    if args.seed < 0:
        raise InputError("--seed", "--seed", args.seed, "must be >= 0")
    engine = EngineSettings(scheduler=args.scheduler, workers=args.workers)
    outputs = Outputs.check({"--json": args.json, "--plot": args.plot})
    result = robustness_sweep(args.runs, args.seed, args.short, engine)
    print(result.report())
    outputs.json("--json", result.to_dict())
    outputs.figure("--plot", result.plot)
    outputs.commit()
    return 0 if result.success else 1


def _cache(args) -> int:
    from . import codegen
    if args.clear:
        print(f"removed {codegen.clear_cache()} files from {codegen.cache_dir()}")
    if args.info or not args.clear:
        print(codegen.cache_info().report())
    return 0


def _write_json(data: dict, path: str | None) -> None:
    text = json.dumps(data, indent=2)
    if path is None:
        print(text)
        return
    try:
        Path(path).write_text(text + "\n")
    except OSError as err:
        raise InputError(path, "--json", path, f"cannot write ({err.strerror})") from None


def _model_outputs(args):
    """The run's file outputs, checked before any work (against every input and each other)."""
    from .outputs import Outputs
    if args.physics == "mechanical" and (args.model or args.write_model):
        option = "--model" if args.model else "--write-model"
        raise InputError(option, option, args.model or args.write_model,
                         "a motor parameter file belongs to --physics thermal")
    inputs = [*args.recordings, *(p for p in (args.model, args.columns) if p)]
    return Outputs.check({"--json": args.json, "--plot": getattr(args, "plot", None),
                          "--write-model": args.write_model}, inputs)


def _write_model(outputs, result: dict) -> None:
    """Write the identified / improved parameter file (--write-model) when the run produced one."""
    from .model.parameters import dumps_parameters, parameters_from_dict
    if not outputs.wanted("--write-model"):
        return
    if result.get("parameter_file") is None:
        logging.getLogger(__name__).warning("no parameter file to write: the fit failed (%s)", result.get("message"))
        return
    params = parameters_from_dict(result["parameter_file"], "--write-model")
    outputs.text("--write-model", dumps_parameters(params))
    outputs.commit()


def _identify(args) -> int:
    outputs = _model_outputs(args)
    if args.physics == "mechanical":
        from .identify.mechanical import identify_mechanical_files
        result = identify_mechanical_files(args.recordings, columns=args.columns)
    else:
        from .identify.thermal import identify_thermal_files
        result = identify_thermal_files(args.recordings, parameters=args.model, columns=args.columns)
    _write_json(result, args.json)
    _write_model(outputs, result)
    return 0


def _diagnose(args) -> int:
    outputs = _model_outputs(args)
    if args.physics == "mechanical":
        from .diagnose.mechanical import diagnose_mechanical_files
        result = diagnose_mechanical_files(args.recordings, plot=args.plot, columns=args.columns)
    else:
        from .diagnose.thermal import diagnose_thermal_files
        result = diagnose_thermal_files(args.recordings, plot=args.plot, parameters=args.model, columns=args.columns)
    _write_json(result, args.json)
    _write_model(outputs, result)
    return 0


def _validate(args) -> int:
    from .outputs import Outputs
    from .validate import validate_files
    inputs = [*args.recordings, args.model, *([args.columns] if args.columns else [])]
    outputs = Outputs.check({"--json": args.json, "--plot": args.plot}, inputs)
    result = validate_files(args.recordings, args.model, args.columns)
    print(result.report())
    outputs.json("--json", result.to_dict())
    if result.success:
        outputs.figure("--plot", result.plot)
    outputs.commit()
    return 0 if result.success else 1


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
    return cmd


def _demo_parser() -> _Parser:
    demo = _Parser(prog="thermo-ddp demo", description="static hold of a payload by the elbow: torque, "
                                                       "current and winding heating")
    demo.add_argument("--payload-kg", type=float, default=40.0, help="payload at the gripper, kg (default %(default)s)")
    demo.add_argument("--hold-s", type=float, default=DEFAULT_HOLD_S, help="duration of the hold, s (default %(default)s)")
    return demo


def _plan_parser(name: str, description: str) -> _Parser:
    cmd = _Parser(prog=f"thermo-ddp {name}", description=description)
    cmd.add_argument("--payload-kg", type=float, default=40.0, help="payload at the gripper, kg (default %(default)s)")
    cmd.add_argument("--hold-s", type=float, default=DEFAULT_HOLD_S, help="requested hold at the goal, s (default %(default)s)")
    cmd.add_argument("--solver", choices=("ddp", "ipopt", "fatrop"), default="ddp",
                     help="solver of the transcribed problem (default %(default)s)")
    if name == "plan":
        cmd.add_argument("--limit-c", type=float, default=None,
                         help="winding limit, °C (default: the model file's [limits] safety_cutoff_c, 84 for the elbow)")
        cmd.add_argument("--model", metavar="TOML", help="elbow parameter file (default: the packaged "
                                                         "models/arm_left_4_joint.toml)")
        cmd.add_argument("--json", metavar="OUT", help="write the plan JSON here (default: none)")
        cmd.add_argument("--plot", metavar="OUT.png", help="write the four-panel figure here (default: none)")
    else:
        cmd.add_argument("--limits-c", type=float, nargs="+", default=None,
                         help="winding limits to compare, °C (default: the elbow file's safety_cutoff_c and "
                              "winding_max_c, 84 and 140)")
    return cmd


def _loop_parser() -> _Parser:
    cmd = _Parser(prog="thermo-ddp loop", description="recordings -> identification -> diagnosis -> improved "
                  "model -> plan -> closed loop, original vs improved model, on the simulated elbow")
    cmd.add_argument("--out", default="loop_out", help="output folder (default %(default)s)")
    cmd.add_argument("--short", action="store_true", help="flag: 30-minute experiments and a 45 s hold")
    cmd.add_argument("--hold-s", type=float, default=None,
                     help="requested hold at the goal, s (default: LoopSettings.hold_s; --short shortens it)")
    cmd.add_argument("--limits-c", type=float, nargs="+", default=[84.0, 140.0],
                     help="winding limits, °C (default %(default)s)")
    cmd.add_argument("--no-oracle", action="store_true", help="flag: skip the run planned with the true parameters")
    return cmd


def _sweep_parser() -> _Parser:
    cmd = _Parser(prog="thermo-ddp sweep", description="randomised closed-loop lifts (plant thermal values "
                  "+-25 %, friction +-30 %, sensor noise, start 30-60 °C) on Dask: a LocalCluster by default")
    cmd.add_argument("--runs", type=int, default=200, help="number of runs (default %(default)s)")
    cmd.add_argument("--short", action="store_true", help="flag: a 5 s hold instead of 15 s")
    cmd.add_argument("--seed", type=int, default=0, help="seed of the sweep; run i's seed is word i of its "
                                                         "stream (default %(default)s)")
    cmd.add_argument("--scheduler", metavar="ADDRESS", default=None,
                     help="Dask scheduler, e.g. tcp://127.0.0.1:8786 (default: a LocalCluster on this machine)")
    cmd.add_argument("--workers", type=int, default=2,
                     help="worker processes of the LocalCluster, count (default %(default)s; ignored with --scheduler)")
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
    try:
        return run(args)
    except InputError as err:
        print(f"thermo-ddp: {err}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
