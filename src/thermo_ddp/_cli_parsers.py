"""The ``thermo-ddp`` argument parsers: one per command, every option with its unit and default as a number.

Global options (``-v``, ``-q``) are taken out of the command line wherever they stand (:func:`split_global`)
before the command's own parser sees it.
"""
from __future__ import annotations

import argparse
import math

from .tasks.limits import DEFAULT_HOLD_S

JSON_STDOUT = "-"  # --json -: the JSON on stdout (the report then goes to stderr)
VERBOSE, QUIET = ("-v", "--verbose"), ("-q", "--quiet")


def number(unit: str):
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


def split_global(argv: list[str]) -> tuple[int, list[str]]:
    """``argv`` without its ``-v``/``-vv``/``--verbose``/``-q``/``--quiet`` (anywhere before ``--``),
    and the verbosity they ask for: -1 quiet, 0 default, 1 INFO, 2 DEBUG and third-party logs."""
    level, rest = 0, []
    for i, arg in enumerate(argv):
        if arg == "--":
            return level, rest + argv[i:]
        if arg in VERBOSE or (arg.startswith("-v") and set(arg[1:]) == {"v"}):
            level = max(level, 0) + (arg.count("v") if arg.startswith("-v") else 1)
        elif arg in QUIET:
            level = -1
        else:
            rest.append(arg)
    return level, rest


class Parser(argparse.ArgumentParser):
    """argparse with a one-line error (the contract: exit 2 with a one-line message)."""

    def error(self, message: str):
        self.exit(2, f"{self.prog}: error: {message}\n")


def _json_option(cmd: Parser, what: str) -> None:
    cmd.add_argument("--json", metavar="OUT", help=f"write the {what} JSON here; '-' prints it on stdout and the "
                                                   "report on stderr (default: none)")


def recording_parser(name: str, description: str, plot: bool) -> Parser:
    cmd = Parser(prog=f"thermo-ddp {name}", description=description)
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
    _json_option(cmd, name)
    if plot:
        cmd.add_argument("--plot", metavar="OUT.png", help=f"write the {name} figure here (default: none)")
    if name == "diagnose":
        cmd.add_argument("--each", action="store_true", help="flag: one diagnosis per recording (a fleet) as Dask "
                         "tasks, and a table of which recordings show which missing physics")
        engine_arguments(cmd)
    return cmd


def engine_arguments(cmd: Parser) -> None:
    cmd.add_argument("--scheduler", metavar="ADDRESS", default=None,
                     help="Dask scheduler, e.g. tcp://127.0.0.1:8786 (default: a LocalCluster on this machine)")
    cmd.add_argument("--workers", type=int, default=2,
                     help="worker processes of the LocalCluster, count (default %(default)s; ignored with --scheduler)")


def _payload_and_hold(cmd: Parser, hold: str) -> None:
    cmd.add_argument("--payload-kg", type=number("kg"), default=40.0,
                     help="payload at the gripper (default %(default)g kg)")
    cmd.add_argument("--hold-s", type=number("s"), default=DEFAULT_HOLD_S, help=f"{hold} (default %(default)g s)")


def demo_parser() -> Parser:
    demo = Parser(prog="thermo-ddp demo", description="static hold of a payload by the elbow: torque, "
                                                      "current and winding heating")
    _payload_and_hold(demo, "duration of the hold")
    return demo


def _fraction_or_file(text: str):
    """``--uncertainty``'s value: a number (checked by the planner: 0 < FRACTION < 1), or ``file`` (what
    the option alone means: the model file's [uncertainty])."""
    return text if text == "file" else number("(a fraction)")(text)


def plan_parser(name: str, description: str) -> Parser:
    cmd = Parser(prog=f"thermo-ddp {name}", description=description)
    _payload_and_hold(cmd, "requested hold at the goal")
    cmd.add_argument("--solver", choices=("ddp", "ipopt", "fatrop"), default="ddp",
                     help="solver of the transcribed problem (default %(default)s)")
    cmd.add_argument("--uncertainty", nargs="?", const="file", default=None, type=_fraction_or_file,
                     metavar="FRACTION", help="plan for every motor of a set: each thermal capacity and resistance, "
                     "the winding resistance and the drive's losses within +-FRACTION (0 < FRACTION < 1); without "
                     "a number, the model file's [uncertainty] intervals (default: none, the file's values only)")
    if name == "plan":
        cmd.add_argument("--limit-c", type=number("°C"), default=None,
                         help="winding limit in °C (default: the model file's [limits] safety_cutoff_c, 84 °C for "
                              "the elbow)")
        cmd.add_argument("--model", metavar="TOML", help="elbow parameter file (default: the packaged "
                                                         "models/arm_left_4_joint.toml)")
        cmd.add_argument("--careful-motion", action=argparse.BooleanOptionalAction, default=True,
                         help="flag, on by default (--no-careful-motion: off): one direction per phase, slow near the "
                              "joint stops, at rest at the end, an acceleration cost")
    else:
        cmd.add_argument("--limits-c", type=number("°C"), nargs="+", default=None,
                         help="winding limits to compare in °C (default: the elbow file's safety_cutoff_c and "
                              "winding_max_c, 84 °C and 140 °C)")
    _json_option(cmd, name)
    cmd.add_argument("--plot", metavar="OUT.png", help="write the figure here (default: none)")
    return cmd


def design_parser() -> Parser:
    from .tasks.experiment import MAX_DURATION_S, ExperimentSettings
    cmd = Parser(prog="thermo-ddp design-experiment", description="plan the experiment (current and motion of the "
                 "elbow) that settles what the recordings leave undetermined, under the winding limit")
    cmd.add_argument("recordings", nargs="+", metavar="REC", help="CSV recordings (contract columns, or any "
                                                                  "columns with --columns); required")
    cmd.add_argument("--model", metavar="TOML", help="parameter file (default: the packaged "
                                                     "models/arm_left_4_joint.toml)")
    cmd.add_argument("--columns", metavar="MAP.toml", help="column map of the recordings (default: contract columns)")
    cmd.add_argument("--limit-c", type=number("°C"), default=None,
                     help="winding limit in °C (default: the model file's [limits] safety_cutoff_c, 84 °C for the "
                          "elbow)")
    cmd.add_argument("--duration-s", type=number("s"), default=ExperimentSettings.duration_s,
                     help=f"longest experiment, in s (default %(default)g s; at most {MAX_DURATION_S:g} s)")
    cmd.add_argument("--out", dest="experiment_csv", metavar="EXP.csv", required=True,
                     help="write the experiment here, in the recording format (time_s, current_a, position, "
                          "velocity); required")
    _json_option(cmd, "experiment")
    cmd.add_argument("--plot", metavar="EXP.png", help="write the planned current, speed and predicted temperatures "
                                                       "here (default: none)")
    return cmd


def loop_parser() -> Parser:
    from .studies.loop import SHORT_DEFAULTS, LoopSettings
    cmd = Parser(prog="thermo-ddp loop", description="recordings -> diagnosis -> designed experiment (if anything "
                 "is undetermined) -> diagnosis again -> improved model -> plan -> closed loop, original vs improved "
                 "model, on the simulated elbow")
    cmd.add_argument("--out", default="loop_out", help="output folder (default %(default)s)")
    cmd.add_argument("--short", action="store_true",
                     help=f"flag: {SHORT_DEFAULTS['heating_s'] / 60:g}-minute experiments, a "
                          f"{SHORT_DEFAULTS['hold_s']:g} s hold and no run with the true parameters")
    cmd.add_argument("--hold-s", type=number("s"), default=None,
                     help=f"requested hold at the goal (default: {LoopSettings.hold_s:g} s; "
                          f"{SHORT_DEFAULTS['hold_s']:g} s with --short)")
    cmd.add_argument("--limits-c", type=number("°C"), nargs="+", default=list(LoopSettings.limits_c),
                     help=f"winding limits in °C (default {' '.join(f'{c:g}' for c in LoopSettings.limits_c)} °C)")
    cmd.add_argument("--no-oracle", action="store_true", help="flag: skip the run planned with the true parameters "
                                                              "(--short skips it anyway)")
    stage = cmd.add_mutually_exclusive_group()
    stage.add_argument("--experiment-s", type=number("s"), default=None,
                       help=f"when the diagnosis leaves items undetermined, design an experiment of at most this "
                            f"long (under the lowest limit, at most the file's cut-off), run it on the robot and "
                            f"diagnose again (default: {LoopSettings.experiment_s:g} s; "
                            f"{SHORT_DEFAULTS['experiment_s']:g} s with --short)")
    stage.add_argument("--no-experiment", action="store_true", help="flag: no designed experiment stage")
    cmd.add_argument("--columns", metavar="MAP.toml", help="column map: the robot logs its recordings in the map's own "
                                                           "column names and the chain reads them through it "
                                                           "(default: contract columns)")
    return cmd


def sweep_parser() -> Parser:
    from .studies.sweep import CONTROLLER, SHORT
    cmd = Parser(prog="thermo-ddp sweep", description="randomised closed-loop lifts (plant thermal values "
                 "+-25 %, friction +-30 %, sensor noise, start 30-60 °C) on Dask: a LocalCluster by default")
    cmd.add_argument("--runs", type=int, default=200, help="number of runs (default %(default)s)")
    cmd.add_argument("--short", action="store_true",
                     help=f"flag: a {SHORT['hold_s']:g} s hold instead of {CONTROLLER['hold_s']:g} s")
    cmd.add_argument("--seed", type=int, default=0, help="seed of the sweep; run i's seed is word i of its "
                                                         "stream (default %(default)s)")
    cmd.add_argument("--nominal-plan", action="store_true",
                     help="flag: the controller holds as long as its model alone allows (default: the hold robust "
                          "to the sweep's +-25 %% thermal spread)")
    engine_arguments(cmd)
    _json_option(cmd, "sweep")
    cmd.add_argument("--plot", metavar="OUT.png", help="write the margin and hold histograms here (default: none)")
    return cmd


def cache_parser() -> Parser:
    from .codegen import DEFAULT_CACHE_MAX_MB
    cmd = Parser(prog="thermo-ddp cache", description="the compiled-library cache: $THERMO_DDP_CACHE (default "
                 f"~/.cache/thermo_ddp), capped at $THERMO_DDP_CACHE_MAX_MB (default {DEFAULT_CACHE_MAX_MB:g} MB; "
                 "least recently used libraries are removed after a build)")
    cmd.add_argument("--clear", action="store_true", help="flag: remove the compiled libraries (nothing else)")
    cmd.add_argument("--info", action="store_true", help="flag: print the folder, libraries and size "
                                                         "(what the command does without flags)")
    return cmd


def top_parser(commands: dict[str, str], version: str) -> Parser:
    """The top level: one line per command (``commands``: name -> one-line summary), global options."""
    listing = "\n".join(f"  {name:<9} {summary}" for name, summary in commands.items())
    top = Parser(prog="thermo-ddp", formatter_class=argparse.RawDescriptionHelpFormatter,
                 description="Thermal-aware planning, identification and diagnosis for a torque-controlled elbow.",
                 epilog=f"commands:\n{listing}\n\n'thermo-ddp COMMAND --help' gives each command's options. -v and -q "
                        "may stand anywhere.\nExit status: 0 a result, 1 the run failed, 2 bad input.")
    top.add_argument("-v", "--verbose", action="count", default=0,
                     help="flag: log the steps (INFO); -vv also debug lines and third-party logs")
    top.add_argument("-q", "--quiet", action="store_true", help="flag: no progress bars, errors only")
    top.add_argument("--version", action="version", version=f"thermo-ddp {version}",
                     help="flag: print the installed version and exit")
    top.add_argument("command", choices=list(commands), metavar="COMMAND", help="required: one of the commands below")
    top.add_argument("args", nargs=argparse.REMAINDER, help="the command's arguments (see COMMAND --help)")
    return top
