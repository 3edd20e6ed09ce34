"""Property tests of bad input (issue 14), bounded and fast: generated CLI numbers, parameter files and
recordings are either refused with one line naming the source, or accepted only when the contract
says they are valid (the oracle is written from docs/architecture.md, not from the implementation)."""
import contextlib
import io
import math
import tomllib

import pytest
import tomli_w
from hypothesis import HealthCheck, assume, given, settings
from hypothesis import strategies as st

from thermo_ddp.cli import main
from thermo_ddp.errors import InputError
from thermo_ddp.model.parameters import load_parameters
from thermo_ddp.recordings import COLUMNS, read_csv

FAST = settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])

ELBOW_AMBIENT_C, ELBOW_WINDING_MAX_C = 26.0, 140.0  # the packaged elbow file (models/arm_left_4_joint.toml)
ELBOW_IDLE_C = 43.0  # seed report: the idle motor settles near 43 °C in a 26 °C room (drive heat)


class WorkStarted(Exception):
    """Raised where a verb would start its work: everything before it was validation."""


def _stop(*args, **kwargs):
    raise WorkStarted


# --- CLI numbers ----------------------------------------------------------------------------------------
numbers = st.one_of(
    st.floats(allow_nan=True, allow_infinity=True).map(repr),
    st.floats(-10.0, 5000.0).map(lambda x: f"{x:.3g}"),
    st.integers(-10, 200).map(str),
    st.sampled_from(["", "abc", "1,5", "0x10", "1e400", "-0", "NaN", "-inf", "1_000", " 7 ", "40kg"]),
)


def _parsed(text: str) -> float | None:
    """The contract's reading of a number argument: a finite float, or None (bad input)."""
    try:
        value = float(text)
    except ValueError:
        return None
    return value if math.isfinite(value) else None


def _inside(value, low, high, open_low=False):
    return value is not None and (low < value if open_low else low <= value) and value <= high


def _cli(argv, monkeypatch_targets):
    """(outcome, stderr): "work" when the verb got past validation, else the exit status."""
    err = io.StringIO()
    with pytest.MonkeyPatch.context() as mp, contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
        for target in monkeypatch_targets:
            mp.setattr(target, _stop)
        try:
            outcome = main(argv)
        except SystemExit as exc:
            outcome = exc.code
        except WorkStarted:
            outcome = "work"
    return outcome, err.getvalue().strip()


def _check(outcome, err, valid):
    if valid:
        assert outcome == "work", err
    else:
        assert outcome == 2 and err and "\n" not in err and "Traceback" not in err, (outcome, err)


@FAST
@given(payload=numbers, hold=numbers)
def test_demo_numbers(payload, hold):
    outcome, err = _cli(["demo", f"--payload-kg={payload}", f"--hold-s={hold}"], ["thermo_ddp.studies.demo.load_model"])
    p, h = _parsed(payload), _parsed(hold)
    _check(outcome, err, _inside(p, 0, 100) and _inside(h, 0, 3600))


@FAST
@given(payload=numbers, hold=numbers, limit=st.one_of(st.none(), numbers))
def test_plan_numbers(payload, hold, limit):
    argv = ["plan", f"--payload-kg={payload}", f"--hold-s={hold}"] + ([] if limit is None else [f"--limit-c={limit}"])
    outcome, err = _cli(argv, ["thermo_ddp.tasks.lift.make_solver"])
    p, h, lim = _parsed(payload), _parsed(hold), None if limit is None else _parsed(limit)
    assume(lim is None or abs(lim - ELBOW_IDLE_C) > 0.5)  # a limit must lie above the winding at rest
    limit_ok = limit is None or _inside(lim, ELBOW_IDLE_C, ELBOW_WINDING_MAX_C, open_low=True)
    _check(outcome, err, _inside(p, 0, 100) and _inside(h, 0, 3600) and limit_ok)


@FAST
@given(hold=numbers, limits=st.lists(numbers, min_size=1, max_size=3))
def test_loop_numbers(hold, limits, tmp_path_factory):
    out = tmp_path_factory.mktemp("loop") / "run"
    argv = ["loop", "--out", str(out), f"--hold-s={hold}", "--limits-c", *limits]
    outcome, err = _cli(argv, ["thermo_ddp.studies.loop.run_loop"])
    h, lims = _parsed(hold), [_parsed(x) for x in limits]
    # a limit text starting with "-" reads as an option to argparse: refused as well
    valid = _inside(h, 0, 3600, open_low=True) and all(
        _inside(v, ELBOW_AMBIENT_C, ELBOW_WINDING_MAX_C, open_low=True) and not t.lstrip().startswith("-")
        for v, t in zip(lims, limits))
    _check(outcome, err, valid)
    assert not out.exists()  # nothing written by a refused (or stopped) run


# --- parameter files ------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def elbow_data(elbow_file):
    return tomllib.loads(elbow_file.read_text())


values = st.one_of(st.floats(allow_nan=True, allow_infinity=True), st.integers(-10 ** 6, 10 ** 6),
                   st.text(max_size=5), st.booleans(), st.lists(st.integers(), max_size=2))


def _contract_valid(data) -> bool:
    """The physical checks the contract lists: finite numbers of the right sign, ambient -50..80 °C,
    limits above ambient, capacities, resistances and the gear ratio > 0, the peak current >= nominal."""
    numbers_ = [v for sec in ("motor", "limits") for v in data[sec].values()]
    numbers_ += [v for k, v in data["thermal"].items() if k != "model"]
    if not all(isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) for v in numbers_):
        return False
    th, m, lim = data["thermal"], data["motor"], data["limits"]
    positive = [v for k, v in {**m, **th}.items() if "capacity" in k or k.endswith("_k_per_w") or k in (
        "resistance_ohm", "gear_ratio", "torque_constant_nm_per_a", "bus_voltage_v", "current_nominal_a")]
    return (-50 <= th["ambient_c"] <= 80 and all(v > 0 for v in positive) and
            all(v > th["ambient_c"] for v in lim.values()) and m["current_peak_a"] >= m["current_nominal_a"])


@FAST
@given(data=st.data())
def test_parameter_files(data, elbow_data, tmp_path):
    doc = {k: dict(v) for k, v in elbow_data.items()}
    section = data.draw(st.sampled_from(["motor", "thermal", "limits"]))
    key = data.draw(st.sampled_from(sorted(doc[section])))
    action = data.draw(st.sampled_from(["set", "set", "set", "drop", "unknown"]))
    if action == "set":
        doc[section][key] = data.draw(values)
    elif action == "drop":
        del doc[section][key]
    else:
        doc[section][key + "_typo"] = 1.0
    path = tmp_path / "fuzzed.toml"
    path.write_text(tomli_w.dumps(doc))
    try:
        params = load_parameters(path)
    except InputError as err:
        msg = str(err)
        assert "\n" not in msg and str(path) in msg and section in msg
        return
    assert action == "set" and _contract_valid(doc), doc[section][key]
    assert params.thermal.ambient_c == doc["thermal"]["ambient_c"]


# --- recordings -------------------------------------------------------------------------------------------
cells = st.one_of(st.floats(allow_nan=True, allow_infinity=True).map(repr), st.floats(-100, 100).map(str),
                  st.sampled_from(["", "x", "1e999", "-", " ", '"1\n2"', "1;2"]))


@FAST
@given(header=st.lists(st.sampled_from(COLUMNS + ("kelvin", "")), min_size=1, max_size=4),
       rows=st.lists(st.lists(cells, min_size=1, max_size=4), max_size=6), sorted_time=st.booleans())
def test_recordings(header, rows, sorted_time, tmp_path):
    if sorted_time:  # half the cases get a plausible time column, to reach the later checks
        rows = [[str(k)] + r[1:] for k, r in enumerate(rows)]
    path = tmp_path / "fuzzed.csv"
    path.write_text("\n".join(",".join(line) for line in [header, *rows]) + "\n")
    try:
        rec = read_csv(path)
    except InputError as err:
        assert "\n" not in str(err) and str(path) in str(err)
        return
    t = rec.time_s
    assert t.size >= 1 and all(math.isfinite(x) for x in t) and all(b > a for a, b in zip(t, t[1:]))
    for column in rec.columns:
        assert all(math.isfinite(x) for x in getattr(rec, column))
