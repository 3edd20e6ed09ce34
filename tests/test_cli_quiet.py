"""Quiet runs: each command, run as a user runs it (a subprocess, the default verbosity), prints a readable
report of at most 40 lines on stdout + stderr, with no Python warning, no traceback and no third-party log
line (Dask's above all). Short settings keep it quick; the shipped simulated elbow recordings are the data."""
import json
import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
ELBOW = [str(ROOT / "data" / "elbow" / "static_3a.csv"), str(ROOT / "data" / "elbow" / "biceps.csv")]
NOISE = re.compile(r"Warning|Traceback|^(distributed|dask|tornado|bokeh|asyncio)[.:]|INFO|DEBUG|it/s\]|\d+%\|",
                   re.MULTILINE)
MAX_LINES = 40


def run(*argv, cwd: Path) -> str:
    env = {k: v for k, v in os.environ.items() if not k.startswith(("PYTHONWARNINGS", "DASK_"))}
    done = subprocess.run([sys.executable, "-m", "thermo_ddp.cli", *argv], cwd=cwd, env=env, capture_output=True,
                          text=True, timeout=1800)
    text = done.stdout + done.stderr
    assert done.returncode == 0, text
    assert len(text.splitlines()) <= MAX_LINES, text
    assert not NOISE.search(text), NOISE.search(text).group(0) + "\n" + text
    assert done.stdout.strip(), "the report goes to stdout"
    return text


@pytest.fixture(scope="module")
def folder(tmp_path_factory):
    return tmp_path_factory.mktemp("quiet")


def test_diagnose_identify_validate(folder):
    text = run("diagnose", *ELBOW, "--json", "d.json", "--plot", "d.png", cwd=folder)
    assert "friction_heating" in text and "drive_heating" in text and "d.png" in text
    text = run("identify", *ELBOW, "--write-model", "m.toml", cwd=folder)
    assert "m.toml" in text and "rmse" in text
    text = run("validate", *ELBOW, "--model", "m.toml", "--plot", "v.png", cwd=folder)
    assert "rmse" in text and "v.png" in text


def test_plan_and_compare(folder):
    assert "140 °C" in run("plan", "--limit-c", "140", "--hold-s", "5", "--json", "p.json", cwd=folder)
    text = run("compare", "--hold-s", "10", "--json", "c.json", "--plot", "c.png", cwd=folder)
    rows = json.loads((folder / "c.json").read_text())["rows"]
    assert [r["limit_c"] for r in rows] == [84, 140] and "c.json" in text and "c.png" in text
    for r in rows:  # the table printed is the JSON's
        assert f"{r['hold_s']:7.1f} {r['peak_winding_c']:11.1f}" in text and r["status"]


def test_loop_short(folder):
    # without the designed-experiment stage (a minute of design): its run is in tests/test_experiment_design.py
    text = run("loop", "--short", "--limits-c", "140", "--hold-s", "20", "--no-experiment", "--out", "loop",
               cwd=folder)
    assert "140 °C" in text and "files in loop/" in text


def test_sweep_short(folder):
    text = run("sweep", "--runs", "2", "--short", "--workers", "1", "--json", "s.json", cwd=folder)
    assert "2 runs" in text and "re-solves that failed" in text
