"""`thermo-ddp VERB --help`: every option of every verb states its default (or that it is a flag or
required), and an option named with a unit gives that unit."""
import argparse

import pytest

from thermo_ddp.cli import COMMANDS, top_parser

UNITS = {"_kg": "kg", "_s": " s", "_c": "°C"}  # option name suffix -> unit the help must name


def _parsers():
    yield "thermo-ddp", top_parser()
    for name, (make_parser, _) in COMMANDS.items():
        yield name, make_parser()


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
        if isinstance(action, argparse._HelpAction):
            continue
        label = f"{name} {'/'.join(action.option_strings) or action.dest}"
        assert action.help, f"{label}: no help"
        text = _expanded_help(parser, action)
        if action.nargs == 0:
            assert "flag" in text, f"{label}: a flag, not said: {text!r}"
        elif action.required or not action.option_strings:
            assert "required" in text or action.nargs == argparse.REMAINDER, f"{label}: {text!r}"
        elif action.default is None:
            assert "default:" in text, f"{label}: what happens without it? {text!r}"
        else:
            assert f"default {action.default}" in text, f"{label}: default {action.default!r} missing: {text!r}"
        for suffix, unit in UNITS.items():
            if action.dest.endswith(suffix):
                assert unit in text, f"{label}: unit {unit.strip()} missing: {text!r}"
        checked += 1
    assert checked > 0


def test_help_exits_0_and_prints_the_defaults(capsys):
    with pytest.raises(SystemExit) as exc:
        COMMANDS["plan"][0]().parse_args(["--help"])
    assert exc.value.code == 0
    out = capsys.readouterr().out
    assert "safety_cutoff_c, 84 for the elbow" in out and "°C" in out
    assert "(default 60.0)" in out  # the one default hold, tasks.limits.DEFAULT_HOLD_S
