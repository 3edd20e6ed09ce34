"""The short reports the command line prints: what was found, the figures that matter, where the files went.

Each report is read from the result's JSON-ready dict (the contracts in docs/architecture.md), so the
terminal and the JSON file never disagree. A report longer than :data:`MAX_LINES` is cut with a line
saying what was left out and where it is.
"""
from __future__ import annotations

from pathlib import Path
from typing import Iterable, Mapping

MAX_LINES = 40

# What each output option holds, for the closing "files:" lines.
RMSE_UNITS = {"thermal": " K", "mechanical": " (effort units: N·m or N)"}  # what a residual is measured in
OUTPUT_NAMES = {"--json": "result JSON", "--plot": "figure", "--write-model": "parameter file"}


def fit_lines(text: str, limit: int = MAX_LINES, rest: str = "the JSON (--json)") -> str:
    """``text`` in at most ``limit`` lines: the first ``limit - 1`` and one saying how many more are in ``rest``."""
    lines = text.splitlines()
    if len(lines) <= limit:
        return text
    return "\n".join(lines[:limit - 1] + [f"  ... {len(lines) - limit + 1} more lines in {rest}"])


def _names(paths: Iterable[str], most: int = 3) -> str:
    names = [Path(p).name for p in paths]
    shown = ", ".join(names[:most])
    return shown + (f" and {len(names) - most} more" if len(names) > most else "")


def _number(value, unit: str = "", digits: int = 3) -> str:
    return "n/a" if value is None else f"{value:.{digits}g}{unit}"


def _heading(verb: str, d: Mapping) -> str:
    recordings = d.get("recordings") or []
    count = f"{len(recordings)} recording{'s' if len(recordings) != 1 else ''}"
    verdict = d.get("status", "?") if d.get("success", True) else f"FAILED ({d.get('status', '?')})"
    return f"{d.get('physics', '')} {verb} of {count} ({_names(recordings)}): {verdict}".lstrip()


def _rows(d: Mapping) -> str:
    rows = d.get("rows") or {}
    return (f"  data: {rows.get('used', '?')} rows used, {rows.get('skipped', 0)} skipped, "
            f"{rows.get('segments', '?')} segment(s)")


def _term_line(term: Mapping, unit: str) -> str:
    values = ", ".join(f"{k} {_number(v, digits=4)}" for k, v in (term.get("parameters") or {}).items())
    return (f"    {term['term']:<18} changes the prediction by {_number(term.get('effect_k'), unit)} rms, "
            f"p = {_number(term.get('p_value'), digits=2)}" + (f" ({values})" if values else ""))


def _first_clause(text: str, most: int = 90) -> str:
    """The gist of a long reason: up to its first colon or parenthesis, at most ``most`` characters."""
    gist = text.split(": ")[0].split(" (")[0].strip()
    return gist if len(gist) <= most else gist[:most - 3] + "..."


def diagnosis_report(d: Mapping) -> str:
    """``thermo-ddp diagnose``: the verdict, the missing physics named with their size and evidence
    strength, what these data cannot decide, and the error before and after."""
    lines = [_heading("diagnosis", d), _rows(d)]
    base, final, valid = d.get("baseline"), d.get("final"), d.get("validation")
    unit = RMSE_UNITS.get(d.get("physics"), "")
    if base:
        regimes = sorted({m.get("regime", "?") for m in d.get("mismatches", [])})
        lines.append(f"  baseline {base['model']}: rmse {_number(base.get('rmse'), unit)}; "
                     f"{len(d.get('mismatches', []))} mismatch interval(s)" + (f" ({', '.join(regimes)})" if regimes else ""))
    named = d.get("missing_physics") or []
    if named:
        lines.append(f"  missing physics ({len(named)}):")
        lines += [_term_line(t, unit) for t in named]
    elif d.get("success"):
        lines.append("  missing physics: none; the model explains these recordings")
    cautions = d.get("not_determinable") or []
    if cautions:
        lines.append("  what these data cannot settle (the JSON's not_determinable: why, and the experiment that would):")
        lines += [f"    {u.get('term', '?'):<18} {_first_clause(u.get('reason', ''))}" for u in cautions]
    if final:
        lines.append(f"  final {final['model']}: rmse {_number(final.get('rmse'), unit)}; "
                     f"{len(d.get('unexplained', []))} unexplained interval(s)")
    if valid:
        lines.append(f"  held-out rmse {_number(valid.get('rmse_before'), unit)} -> "
                     f"{_number(valid.get('rmse_after'), unit)} ({valid.get('method', '').split(':')[0]})")
    lines.append(f"  {d.get('message', '')}")
    return "\n".join(lines)


def identification_report(d: Mapping) -> str:
    """``thermo-ddp identify``: the model, its error and each parameter with its standard error and
    95 % interval."""
    lines = [_heading("identification", d), _rows(d),
             f"  model {d.get('model', '?')}: rmse {_number(d.get('rmse'), RMSE_UNITS.get(d.get('physics'), ''))} "
             f"on {d.get('n_samples', '?')} samples"]
    params, stderr, ci = d.get("parameters") or {}, d.get("stderr") or {}, d.get("confidence_95") or {}
    if params:
        lines.append("  parameters (± standard error; 95 % interval):")
    for name, value in params.items():
        interval = ci.get(name)
        lines.append(f"    {name:<32} {value:12.5g} ± {_number(stderr.get(name), digits=2):<8}"
                     + (f" [{interval[0]:.4g}, {interval[1]:.4g}]" if interval else ""))
    if not d.get("success", True):
        lines.append(f"  {d.get('message', '')}")
    return "\n".join(lines)


def files_report(written: Mapping[str, Path]) -> str:
    """Where the files went: one line per output written, named for what it holds."""
    return "\n".join(f"  {OUTPUT_NAMES.get(option, option)} ({option}) -> {path}" for option, path in written.items())
