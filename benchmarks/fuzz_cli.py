"""Fuzz the ``thermo-ddp`` command line with generated bad and odd inputs; count each outcome class.

    python benchmarks/fuzz_cli.py [--cases 2000] [--seed 0] [--timeout-s 120] [--subprocess-sample 60] [--kinds 0 1 ...]

Each case is an argument list run in a fresh folder holding its inputs (a thermal and a mechanical
recording, a parameter file, possibly fuzzed ones) and earlier outputs (JSON, PNG, a run folder of
another tool). Cases run in-process in a worker (cheap: one import), which the driver kills and
restarts when a case outlives ``--timeout-s``; a sample also runs as a real ``thermo-ddp`` process, whose
exit status must match. Outcome classes:

- ``ok``: exit 0, the output sane; ``refused``: exit 2 with exactly one line on stderr;
  ``failed``: exit 1 (ran but failed; any JSON asked for is written and says ``success: false``);
- faults: ``traceback`` (an exception escaped, or a traceback on stderr), ``unclear_refusal`` (exit 2
  without exactly one line), ``hang``, ``data_loss`` (an input or a file not named as an output changed,
  anything changed by a refused run, a temporary file left behind), ``silent_garbage`` (exit 0 with NaN/inf,
  a physically absurd value, or ``success: false``), ``subprocess_mismatch``.

Counts, the run time and the first examples of each fault go to benchmarks/results/fuzz_cli.json.
"""
from __future__ import annotations

import argparse
import contextlib
import hashlib
import io
import json
import logging
import math
import os
import random
import re
import selectors
import shutil
import subprocess
import sys
import tempfile
import time
import traceback
from pathlib import Path

from _common import write

FAULTS = ("traceback", "unclear_refusal", "hang", "data_loss", "silent_garbage", "subprocess_mismatch")
CLASSES = ("ok", "refused", "failed") + FAULTS
WINDING_RANGE_C = (-60.0, 400.0)  # beyond: no room, no insulation (models/*.toml bounds)
NOISE_LIMIT_K = 0.5  # a casing sensor's noise is tenths of a kelvin: a fit 10x worse does not explain the data


# --------------------------------------------------------------------------------------------
# The worker: runs cases in-process, one JSON line per case
# --------------------------------------------------------------------------------------------
class _CurrentStderr(io.TextIOBase):
    """Log records go to whatever sys.stderr is while the case runs."""

    def write(self, text):
        return sys.stderr.write(text)


def worker() -> None:
    from thermo_ddp.cli import main

    logging.basicConfig(level=logging.WARNING, stream=_CurrentStderr(), format="%(name)s: %(message)s")
    for line in sys.stdin:
        case = json.loads(line)
        os.chdir(case["cwd"])
        out, err, escaped = io.StringIO(), io.StringIO(), None
        with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
            try:
                code = main(case["argv"])
            except SystemExit as exc:
                code = exc.code if isinstance(exc.code, int) else 1
            except BaseException:  # noqa: BLE001 - the point: an exception escaping main is a fault
                code, escaped = None, traceback.format_exc()
        print(json.dumps({"code": code, "stdout": out.getvalue()[-20000:], "stderr": err.getvalue()[-4000:],
                          "escaped": escaped}), flush=True)


class Worker:
    """The driver's handle on one worker process; ``run`` returns None on a timeout (worker killed)."""

    def __init__(self):
        self.proc = subprocess.Popen([sys.executable, __file__, "--worker"], stdin=subprocess.PIPE,
                                     stdout=subprocess.PIPE, text=True, bufsize=1)
        self.sel = selectors.DefaultSelector()
        self.sel.register(self.proc.stdout, selectors.EVENT_READ)

    def run(self, argv, cwd, timeout_s):
        self.proc.stdin.write(json.dumps({"argv": argv, "cwd": str(cwd)}) + "\n")
        self.proc.stdin.flush()
        if not self.sel.select(timeout_s):
            self.close()
            return None
        return json.loads(self.proc.stdout.readline())

    def close(self):
        self.proc.kill()
        self.proc.wait()


# --------------------------------------------------------------------------------------------
# Case generation
# --------------------------------------------------------------------------------------------
BAD_NUMBERS = ["inf", "-inf", "nan", "1e6", "1e9", "1e308", "1e400", "-1", "-0.5", "", "abc", "1,5", "0x10",
               "40kg", "1e-320", "100.5", "-300"]


def number(rng, good):
    return rng.choice(good) if rng.random() < 0.5 else rng.choice(BAD_NUMBERS + good)


def thermal_csv(rng, rows=40, fuzz=0.0):
    """A short heating/cooling recording; with probability ``fuzz`` per cell a bad cell."""
    bad = ["nan", "inf", "", "x", "1e300", "-1e300", "5000", "-400", '"1\n2"']
    lines = ["time_s,current_a,temperature_c"]
    for k in range(rows):
        cells = [f"{10.0 * k:g}", f"{2.0 if k < rows // 2 else 0.0:g}", f"{30 + 5 * (1 - math.exp(-k / 8)):.3f}"]
        cells = [rng.choice(bad) if rng.random() < fuzz else c for c in cells]
        lines.append(",".join(cells))
    if fuzz and rng.random() < 0.3:
        header = rng.choice(["time,current_a,temperature_c", "time_s,current_a,temperature_k", "time_s,time_s,x", ""])
        lines[0] = header
    if fuzz and rng.random() < 0.2:
        lines[1:] = lines[1:][::-1]  # time decreasing
    return "\n".join(lines) + "\n"


def noise_csv(rng, rows=120):
    """Current and temperature drawn at random each sample: a recording no thermal model explains."""
    lines = ["time_s,current_a,temperature_c"]
    lines += [f"{10 * k},{rng.uniform(-10, 10):.3f},{rng.uniform(20, 120):.3f}" for k in range(rows)]
    return "\n".join(lines) + "\n"


def mechanical_csv(rng, rows=400, fuzz=0.0):
    lines = ["time_s,position,velocity,effort"]
    for k in range(rows):
        t = 0.01 * k
        q, v = 0.5 * math.sin(2 * t), math.cos(2 * t)
        cells = [f"{t:.2f}", f"{q:.5f}", f"{v:.5f}", f"{3 * v + 2 * math.tanh(v / 0.05) + 0.1 * rng.gauss(0, 1):.5f}"]
        cells = [rng.choice(["nan", "", "1e300", "q"]) if rng.random() < fuzz else c for c in cells]
        lines.append(",".join(cells))
    return "\n".join(lines) + "\n"


PARAM_VALUES = ["nan", "inf", "-inf", "0.0", "-1.0", "1e-300", "1e300", '"text"', "true", "[1, 2]", "-500.0",
                "1e4", "0.5", "1e-3", "1e3", "99.0", "5e3", "0.02", "250.0"]  # the last: in range, extreme


def fuzzed_model(rng, text):
    """The elbow file with one value replaced, a line removed, or an unknown key added."""
    lines = text.splitlines()
    keyed = [i for i, ln in enumerate(lines) if re.match(r"^[a-z_0-9]+ = ", ln)]
    i = rng.choice(keyed)
    action = rng.random()
    if action < 0.7:
        lines[i] = lines[i].split(" = ")[0] + " = " + rng.choice(PARAM_VALUES)
    elif action < 0.85:
        del lines[i]
    else:
        lines.insert(i, "mystery_key = 1.0")
    return "\n".join(lines) + "\n"


def make_case(rng, k, folder, elbow_text, kinds=tuple(range(10))):
    """The argument list of case ``k``; its files written into ``folder``."""
    (folder / "rec.csv").write_text(thermal_csv(rng))
    (folder / "mech.csv").write_text(mechanical_csv(rng))
    (folder / "model.toml").write_text(elbow_text)
    (folder / "earlier.json").write_text('{"earlier": true}\n')
    (folder / "earlier.png").write_bytes(b"\x89PNG earlier")
    (folder / "theirs").mkdir()
    (folder / "theirs" / "notes.txt").write_text("another tool's file")
    outputs = ["out.json", "earlier.json", "rec.csv", "model.toml", "mech.csv", "theirs", "no/such/dir/x.json",
               "", ".", "earlier.png", "out.xyz", "theirs/notes.txt"]
    kind = kinds[k % len(kinds)]
    if kind == 0:  # demo numbers
        return ["demo", f"--payload-kg={number(rng, ['0', '10', '40', '99'])}",
                f"--hold-s={number(rng, ['0', '1', '30', '120', '600'])}"]
    if kind == 1:  # plan numbers and outputs (a valid plan is cheap: short hold)
        argv = ["plan", f"--payload-kg={number(rng, ['10', '40'])}", f"--hold-s={number(rng, ['0', '1', '3'])}"]
        if rng.random() < 0.5:
            argv.append(f"--limit-c={number(rng, ['84', '120', '140'])}")
        if rng.random() < 0.5:
            argv += ["--json", rng.choice(outputs)]
        if rng.random() < 0.3:
            argv += ["--plot", rng.choice(outputs + ["out.png"])]
        if rng.random() < 0.3:
            argv += ["--model", "model.toml"]
        return argv
    if kind == 2:  # fuzzed parameter files
        (folder / "fuzzed.toml").write_text(fuzzed_model(rng, elbow_text))
        return ["plan", "--model", "fuzzed.toml", "--hold-s", "1", "--json", "out.json"]
    if kind == 3:  # compare and loop: numbers, --out
        if rng.random() < 0.5:
            return ["compare", "--hold-s", number(rng, ["1"]), "--limits-c",
                    *[number(rng, ["84", "140"]) for _ in range(rng.randint(1, 3))]]
        out = rng.choice(["earlier.json", "theirs", "no/such/run", "", "rec.csv"])
        return ["loop", "--short", "--out", out, f"--hold-s={number(rng, ['20'])}"]
    if kind == 5 and rng.random() < 0.3:  # a garbage recording: noise no thermal model explains
        (folder / "fuzzed.csv").write_text(noise_csv(rng))
        return ["diagnose", "fuzzed.csv", "--json", "out.json"]
    if kind in (4, 5):  # fuzzed thermal recordings
        (folder / "fuzzed.csv").write_text(thermal_csv(rng, rows=rng.randint(0, 60), fuzz=rng.choice([0.0, 0.02, 0.1])))
        verb = rng.choice(["identify", "identify", "diagnose"])
        argv = [verb, "fuzzed.csv"]
        if rng.random() < 0.5:
            argv += ["--json", rng.choice(outputs)]
        return argv
    if kind == 6:  # fuzzed mechanical recordings
        (folder / "fuzzed.csv").write_text(mechanical_csv(rng, rows=rng.randint(0, 400), fuzz=rng.choice([0.0, 0.01])))
        return [rng.choice(["identify", "diagnose"]), "--physics", "mechanical", "fuzzed.csv",
                "--json", rng.choice(["out.json", "fuzzed.csv", "earlier.json"])]
    if kind == 7:  # outputs onto inputs and odd places
        verb = rng.choice(["identify", "diagnose"])
        argv = [verb, "rec.csv", "--json", rng.choice(outputs)]
        if verb == "diagnose" and rng.random() < 0.7:
            argv += ["--plot", rng.choice(outputs + ["out.png"])]
        return argv
    if kind == 8:  # argument structure
        return rng.choice([
            [], ["frobnicate"], ["plan", "--hold-s"], ["plan", "--holds", "3"], ["demo", "extra"],
            ["identify"], ["identify", "--physics", "kinetic", "rec.csv"], ["diagnose", "missing.csv"],
            ["identify", "rec.csv", "rec.csv"], ["plan", "--solver", "newton"], ["cache", "--bogus"],
            ["identify", "theirs"], ["identify", "model.toml"], ["plan", "--model", "rec.csv"],
            ["plan", "--model", "missing.toml"], ["demo", "--payload-kg", "40", "--payload-kg", "nan"],
            ["identify", "--json", "out.json"], ["plan", "--json"], ["loop", "--out"],
        ])
    return ["demo", f"--hold-s={rng.choice(['1', '60', '600', '3600'])}",  # kind 9: valid work, sane output?
            f"--payload-kg={rng.choice(['0', '5', '40', '60', '100'])}"]


# --------------------------------------------------------------------------------------------
# Classification
# --------------------------------------------------------------------------------------------
def snapshot(folder: Path) -> dict[str, str]:
    return {str(p.relative_to(folder)): hashlib.sha256(p.read_bytes()).hexdigest()
            for p in sorted(folder.rglob("*")) if p.is_file()}


def _strict_json(text):
    def refuse(name):
        raise ValueError(f"non-finite JSON constant {name}")
    return json.loads(text, parse_constant=refuse)


def garbage_in(argv, stdout: str, folder: Path) -> str | None:
    """Why an exit-0 result is garbage (None: sane)."""
    if re.search(r"\b(nan|inf)\b", stdout, re.IGNORECASE):
        return "nan/inf printed"
    for line in stdout.splitlines():
        m = re.match(r"\s*winding after\s+\d+ s\s+(-?[\d.]+) °C", line)
        if m and not WINDING_RANGE_C[0] <= float(m.group(1)) <= WINDING_RANGE_C[1]:
            return f"absurd winding temperature printed: {line.strip()}"
    docs = []
    if "--json" in argv and (folder / "out.json").is_file():
        docs.append((folder / "out.json").read_text())
    elif stdout.lstrip().startswith("{"):
        docs.append(stdout)
    for text in docs:
        try:
            d = _strict_json(text)
        except ValueError as err:
            return f"JSON: {err}"
        if d.get("success") is False:
            return "exit 0 with success: false"
        final = d.get("final") or {}
        if argv[0] == "diagnose" and final.get("rmse", 0.0) > NOISE_LIMIT_K * 10 and d.get("status") != "model_does_not_fit":
            return f"diagnosed as fine with a final rmse of {final['rmse']:.1f} K (status {d.get('status')})"
        for key in ("winding_c", "casing_c"):
            flat = [x for row in d.get(key, []) for x in row]
            if flat and not (WINDING_RANGE_C[0] <= min(flat) and max(flat) <= WINDING_RANGE_C[1]):
                return f"absurd {key}: {min(flat):.1f}..{max(flat):.1f} °C"
    return None


def classify(argv, result, before, after, folder) -> tuple[str, str]:
    """(class, detail) of one case."""
    if result is None:
        return "hang", ""
    code, err = result["code"], result["stderr"].strip()
    if result["escaped"] or "Traceback (most recent call last)" in err:
        return "traceback", (result["escaped"] or err)[-1500:]
    asked = outputs_of(argv)
    changed = sorted(k for k in before if after.get(k) != before[k])
    # an input, or any file not asked for, must never change; a refused run changes nothing (a run that
    # failed writes its JSON: the contract's exit 1)
    lost = [k for k in changed if k not in asked or k in inputs_of(argv) or code not in (0, 1)]
    temporaries = [k for k in after if k not in before and Path(k).name.startswith(".")]
    if lost or temporaries:
        return "data_loss", f"changed {lost}, temporaries {temporaries}"
    if code == 2:
        return ("refused", err) if err and "\n" not in err else ("unclear_refusal", err)
    if code == 1:
        if "--json" in argv and (folder / "out.json").is_file() and "out.json" in argv:
            try:
                if _strict_json((folder / "out.json").read_text()).get("success") is not False:
                    return "silent_garbage", "exit 1 but the JSON says success"
            except ValueError as exc:
                return "silent_garbage", f"exit 1, JSON: {exc}"
        return "failed", err[-300:]
    if code == 0:
        why = garbage_in(argv, result["stdout"], folder)
        return ("silent_garbage", why) if why else ("ok", "")
    return "traceback", f"exit status {code}: {err[-300:]}"


def inputs_of(argv):
    outs = outputs_of(argv)
    return [a for a in argv if not a.startswith("-") and a not in outs]


def outputs_of(argv):
    return [argv[i + 1] for i, a in enumerate(argv[:-1]) if a in ("--json", "--plot", "--out", "--write-model")]


# --------------------------------------------------------------------------------------------
# Driver
# --------------------------------------------------------------------------------------------
def subprocess_code(argv, cwd, timeout_s):
    exe = Path(sys.executable).with_name("thermo-ddp")
    try:
        return subprocess.run([str(exe), *argv], cwd=cwd, capture_output=True, timeout=timeout_s).returncode
    except subprocess.TimeoutExpired:
        return None


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--cases", type=int, default=2000)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--timeout-s", type=float, default=120.0)
    parser.add_argument("--subprocess-sample", type=int, default=60, help="cases also run as real processes")
    parser.add_argument("--kinds", type=int, nargs="+", default=list(range(10)),
                        help="case kinds to generate (0-9, see make_case; default all, in turn)")
    parser.add_argument("--worker", action="store_true", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.worker:
        return worker()
    from thermo_ddp.model.parameters import packaged_parameter_file
    elbow_text = packaged_parameter_file("arm_left_4_joint").read_text()
    rng = random.Random(args.seed)
    counts = {c: 0 for c in CLASSES}
    examples: dict[str, list] = {c: [] for c in FAULTS + ("failed",)}
    by_verb: dict[str, dict[str, int]] = {}
    refusals: dict[str, dict] = {}  # one example of each kind of refusal message, to read
    sample = set(random.Random(args.seed + 1).sample(range(args.cases), min(args.subprocess_sample, args.cases)))
    start, runner = time.perf_counter(), Worker()
    root = Path(tempfile.mkdtemp(prefix="thermo-ddp-fuzz-"))
    try:
        for k in range(args.cases):
            folder = root / f"case{k:05d}"
            folder.mkdir()
            argv = make_case(rng, k, folder, elbow_text, tuple(args.kinds))
            twin = root / f"twin{k:05d}"
            if k in sample:  # the same files for the real process
                shutil.copytree(folder, twin)
            before = snapshot(folder)
            result = runner.run(argv, folder, args.timeout_s)
            if result is None:
                runner = Worker()
            cls, detail = classify(argv, result, before, snapshot(folder), folder)
            if k in sample and cls != "hang":
                code = subprocess_code(argv, twin, args.timeout_s)
                if code != result["code"] and cls != "traceback":
                    cls, detail = "subprocess_mismatch", f"in-process {result['code']}, process {code}"
            shutil.rmtree(twin, ignore_errors=True)
            counts[cls] += 1
            verb = argv[0] if argv else "(none)"
            by_verb.setdefault(verb, {}).setdefault(cls, 0)
            by_verb[verb][cls] += 1
            if cls in examples and len(examples[cls]) < 8:
                examples[cls].append({"argv": argv, "detail": detail})
            shape = re.sub(r"[\d.e+-]+|'[^']*'|\S+\.(csv|toml|json|png)", "#", detail)
            if cls == "refused" and shape not in refusals and len(refusals) < 40:
                refusals[shape] = {"argv": argv, "message": detail}
            if (k + 1) % 100 == 0:
                print(f"{k + 1} cases, {time.perf_counter() - start:.0f} s: "
                      f"{ {c: n for c, n in counts.items() if n} }", flush=True)
            shutil.rmtree(folder, ignore_errors=True)
    finally:
        runner.close()
        shutil.rmtree(root, ignore_errors=True)
    elapsed = time.perf_counter() - start
    write("fuzz_cli", {"cases": args.cases, "seed": args.seed, "kinds": args.kinds, "timeout_s": args.timeout_s,
                       "subprocess_sample": len(sample), "elapsed_s": round(elapsed, 1), "counts": counts,
                       "faults": sum(counts[c] for c in FAULTS), "by_verb": by_verb, "examples": examples,
                       "refusal_samples": list(refusals.values())})
    print(json.dumps(counts))
    return 1 if any(counts[c] for c in FAULTS) else 0


if __name__ == "__main__":
    sys.exit(main())
