"""`thermo-ddp --help`, `COMMAND --help`, `--version`, -v/-q: what a new user reads first. Every option of
every command states its default as a number with its unit (or that it is a flag or required); the top
level lists each command in one line, with no Sphinx markup."""
import argparse
import importlib.metadata
import re

import pytest

import thermo_ddp
from thermo_ddp._cli_parsers import split_global
from thermo_ddp.cli import COMMANDS, main, top_parser

UNITS = {"_kg": "kg", "_s": " s", "_c": "°C"}  # option name suffix -> unit the help must name


def _parsers():
    yield "thermo-ddp", top_parser()
    for name, command in COMMANDS.items():
        yield name, command.parser()


def _expanded_help(parser: argparse.ArgumentParser, action: argparse.Action) -> str:
    params = dict(vars(action), prog=parser.prog)
    for key, value in params.items():
        if isinstance(value, (list, tuple)) and key == "choices":
            params[key] = ", ".join(map(str, value))
    return action.help % params


@pytest.mark.parametrize("name, parser", list(_parsers()), ids=[n for n, _ in _parsers()])
def test_every_option_states_its_default_and_unit(name, parser):
    checked = 0
    for action in parser._actions:
        if isinstance(action, (argparse._HelpAction, argparse._VersionAction)):
            continue
        label = f"{name} {'/'.join(action.option_strings) or action.dest}"
        assert action.help, f"{label}: no help"
        text = _expanded_help(parser, action)
        assert "Settings." not in text, f"{label}: a default named by its Python attribute: {text!r}"
        unit = next((u for suffix, u in UNITS.items() if action.dest.endswith(suffix)), "")
        if action.nargs == 0 or isinstance(action, argparse._CountAction):
            assert "flag" in text, f"{label}: a flag, not said: {text!r}"
        elif action.required or not action.option_strings:
            assert "required" in text or action.nargs == argparse.REMAINDER, f"{label}: {text!r}"
        elif action.default is None:
            assert "default:" in text, f"{label}: what happens without it? {text!r}"
            assert not unit or re.search(rf"\d {unit.strip()}", text), f"{label}: default not a number in {unit}: {text!r}"
        elif isinstance(action.default, (int, float)) and unit:
            assert f"default {action.default:g} {unit.strip()}" in text, f"{label}: default {action.default!r}: {text!r}"
        else:
            shown = " ".join(f"{v:g}" for v in action.default) if isinstance(action.default, list) else action.default
            assert f"default {shown}" in text, f"{label}: default {action.default!r} missing: {text!r}"
        if unit:
            assert unit in text, f"{label}: unit {unit.strip()} missing: {text!r}"
        checked += 1
    assert checked > 0


def test_top_level_help_lists_each_command_in_one_line_without_markup(capsys):
    with pytest.raises(SystemExit) as exc:
        main(["--help"])
    assert exc.value.code == 0
    out = capsys.readouterr().out
    for name, command in COMMANDS.items():
        line, = [ln for ln in out.splitlines() if ln.split()[:1] == [name]]
        assert command.summary in line
    assert not re.search(r":(class|func|mod|data|meth):|``", out)


def test_help_gives_defaults_as_numbers_with_units(capsys):
    with pytest.raises(SystemExit) as exc:
        main(["plan", "--help"])
    assert exc.value.code == 0
    out = capsys.readouterr().out
    assert "84 °C for the elbow" in out and "(default 60 s)" in out and "(default 40 kg)" in out
    with pytest.raises(SystemExit):
        main(["loop", "--help"])
    out = capsys.readouterr().out
    assert "LoopSettings" not in out and "default: 60 s; 45 s with --short" in " ".join(out.split())


def test_version_is_the_installed_distributions(capsys):
    installed = importlib.metadata.version("thermo-ddp")
    assert thermo_ddp.__version__ == installed
    with pytest.raises(SystemExit) as exc:
        main(["--version"])
    assert exc.value.code == 0 and capsys.readouterr().out.strip() == f"thermo-ddp {installed}"


@pytest.mark.parametrize("argv, level, rest", [
    (["-v", "demo"], 1, ["demo"]),
    (["demo", "-v", "--payload-kg", "10"], 1, ["demo", "--payload-kg", "10"]),
    (["demo", "--payload-kg", "10", "-vv"], 2, ["demo", "--payload-kg", "10"]),
    (["demo", "--quiet"], -1, ["demo"]),
    (["-q", "demo", "--", "-v"], -1, ["demo", "--", "-v"]),
])
def test_verbosity_is_taken_anywhere(argv, level, rest):
    assert split_global(argv) == (level, rest)


def test_quiet_after_the_command_is_accepted(capsys):
    assert main(["demo", "--payload-kg", "10", "-q"]) == 0
    assert "10 kg" in capsys.readouterr().out


@pytest.mark.parametrize("verbosity, shown, hidden", [
    (0, ["thermo_ddp.cli warn"], ["thermo_ddp.loop step", "thermo_ddp.solvers.ddp solve", "distributed.scheduler start"]),
    (1, ["thermo_ddp.loop step", "thermo_ddp.solvers.ddp slow"], ["thermo_ddp.solvers.ddp solve",
                                                                   "thermo_ddp.mpc.controller period",
                                                                   "distributed.scheduler start"]),
    (2, ["thermo_ddp.solvers.ddp solve", "thermo_ddp.mpc.controller period", "distributed.scheduler start"], []),
    (-1, [], ["thermo_ddp.cli warn", "thermo_ddp.loop step"]),
])
def test_verbosity_levels_keep_per_solve_and_third_party_lines_out_unless_asked(verbosity, shown, hidden, capsys):
    """-v shows the steps, not one line per solve or per control period; Dask speaks only with -vv."""
    import logging

    from thermo_ddp._logs import configure_logging
    configure_logging(verbosity)
    logging.getLogger("thermo_ddp.cli").warning("warn")
    logging.getLogger("thermo_ddp.loop").info("step")
    logging.getLogger("thermo_ddp.solvers.ddp").info("solve")
    logging.getLogger("thermo_ddp.solvers.ddp").warning("slow")
    logging.getLogger("thermo_ddp.mpc.controller").warning("period")
    logging.getLogger("distributed.scheduler").info("start")
    err = capsys.readouterr().err
    configure_logging(0)
    for line in shown:
        assert line.replace(" ", ": ", 1) in err
    for line in hidden:
        assert line.replace(" ", ": ", 1) not in err
