"""Run every benchmark, one after the other (each in its own process), results in benchmarks/results/.

    python benchmarks/run_all.py [--quick] [--only lift_ocp mpc_step ...] [--skip arm_crocoddyl]

--quick passes --quick to the benchmarks that have it (fewer repeats) and fewer repeats to the
others; any other benchmarks/bench_*.py is run too, with no arguments, except the optional ones (OPTIONAL:
their own venv and make target). The crocoddyl benchmark creates .venv-croco on first use (or uses
$CROCODDYL_PYTHON).
"""
from __future__ import annotations

import argparse
import subprocess
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
BENCHMARKS = {  # name: (script, arguments for --quick)
    "model_eval": ("bench_model_eval.py", ["--repeats", "3"]),
    "lift_ocp": ("bench_lift_ocp.py", ["--quick"]),
    "mpc_step": ("bench_mpc_step.py", ["--quick"]),
    "arm_crocoddyl": ("bench_arm_crocoddyl.py", ["--quick"]),
    "ddp_backends": ("bench_ddp_backends.py", ["--quick", "--mpc-steps", "5", "--repeats", "5"]),
    "thermal_diagnosis": ("bench_thermal_diagnosis.py", ["--seeds", "8", "--pairs", "4", "--repeats", "2"]),
}
OPTIONAL = {"lift_drake": "make bench-drake"}  # pydrake is not in the project's venv
BENCHMARKS.update({p.stem[len("bench_"):]: (p.name, []) for p in sorted(HERE.glob("bench_*.py"))
                   if p.stem[len("bench_"):] not in {**BENCHMARKS, **OPTIONAL}})


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true")
    parser.add_argument("--only", nargs="*", choices=sorted(BENCHMARKS), default=None)
    parser.add_argument("--skip", nargs="*", choices=sorted(BENCHMARKS), default=())
    args = parser.parse_args()
    names = [n for n in (args.only or BENCHMARKS) if n not in args.skip]
    failed = []
    for name in names:
        script, quick_args = BENCHMARKS[name]
        print(f"== {name} ({script})", flush=True)
        start = time.perf_counter()
        done = subprocess.run([sys.executable, str(HERE / script), *(quick_args if args.quick else [])], cwd=HERE)
        print(f"== {name}: {'ok' if done.returncode == 0 else 'FAILED'} in {time.perf_counter() - start:.0f} s",
              flush=True)
        if done.returncode:
            failed.append(name)
    if failed:
        sys.exit(f"failed: {', '.join(failed)}")


if __name__ == "__main__":
    main()
