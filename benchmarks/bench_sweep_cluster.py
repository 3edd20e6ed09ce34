"""A sweep on a cluster started by hand, with one worker killed mid-sweep: every run completes and equals
the default LocalCluster run seed for seed.

Starts `dask scheduler` and two `dask worker` processes (one thread each) on the loopback address, runs
`thermo-ddp sweep --runs R --short --seed S --scheduler tcp://127.0.0.1:PORT`, kills one worker (its nanny
too: the machine is gone) once the sweep is under way, then runs the same sweep on the default LocalCluster
and compares the runs. Writes results/sweep_cluster.json.

Usage: python benchmarks/bench_sweep_cluster.py [--runs 6] [--seed 3] [--kill-after-s 8]
"""
from __future__ import annotations

import argparse
import json
import os
import signal
import socket
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from _common import write

BIN = Path(sys.executable).parent
COMPARED = ("max_winding_c", "achieved_hold_s", "nominal_hold_s", "margin_c", "violations", "cutoff_trips", "draw")


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def start(args: list[str], log: Path) -> subprocess.Popen:
    return subprocess.Popen(args, stdout=log.open("w"), stderr=subprocess.STDOUT, start_new_session=True)


def wait_for_workers(address: str, count: int, timeout_s: float = 60.0) -> None:
    from distributed import Client
    with Client(address, timeout="20s") as client:
        client.wait_for_workers(count, timeout=timeout_s)


def kill_a_busy_worker(address: str) -> list[str]:
    """Kill a worker that is running a task, with its nanny (the machine is gone); the tasks it held."""
    from distributed import Client
    with Client(address, timeout="20s") as client:
        pids = client.run(os.getpid)
        busy = {w: keys for w, keys in client.processing().items() if keys}
    if not busy:
        sys.exit("no worker was busy: start the kill earlier (--kill-after-s)")
    worker, keys = next(iter(busy.items()))
    os.killpg(os.getpgid(pids[worker]), signal.SIGKILL)
    return [str(k) for k in keys]


def sweep(argv: list[str], out: Path) -> tuple[dict, float]:
    t0 = time.perf_counter()
    done = subprocess.run([str(BIN / "thermo-ddp"), "sweep", *argv, "--json", str(out)], check=False)
    wall = time.perf_counter() - t0
    if done.returncode != 0:
        sys.exit(f"thermo-ddp sweep {' '.join(argv)} exited {done.returncode}")
    return json.loads(out.read_text()), wall


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=6)
    ap.add_argument("--seed", type=int, default=3)
    ap.add_argument("--kill-after-s", type=float, default=5.0)
    args = ap.parse_args()
    work = Path(tempfile.mkdtemp(prefix="sweep-cluster-"))
    port = free_port()
    address = f"tcp://127.0.0.1:{port}"
    procs = [start([str(BIN / "dask"), "scheduler", "--host", "127.0.0.1", "--port", str(port),
                    "--dashboard-address", ":0"], work / "scheduler.log")]
    try:
        time.sleep(3)
        workers = [start([str(BIN / "dask"), "worker", address, "--nthreads", "1", "--nworkers", "1",
                          "--dashboard-address", ":0"], work / f"worker{i}.log") for i in range(2)]
        procs += workers
        wait_for_workers(address, 2)
        cli = ["--runs", str(args.runs), "--short", "--seed", str(args.seed)]
        t0 = time.perf_counter()
        running = subprocess.Popen([str(BIN / "thermo-ddp"), "sweep", *cli, "--scheduler", address,
                                    "--json", str(work / "cluster.json")])
        time.sleep(args.kill_after_s)
        still_running = running.poll() is None
        lost = kill_a_busy_worker(address)
        killed_at = time.perf_counter() - t0
        code = running.wait()
        cluster_wall = time.perf_counter() - t0
        if code != 0:
            sys.exit(f"cluster sweep exited {code}")
        cluster = json.loads((work / "cluster.json").read_text())
    finally:
        for p in procs:
            try:
                os.killpg(p.pid, signal.SIGTERM)
            except ProcessLookupError:
                pass
    local, local_wall = sweep(cli, work / "local.json")
    by_seed = {r["seed"]: r for r in local["runs"]}
    equal = all(r["seed"] in by_seed and all(r[k] == by_seed[r["seed"]][k] for k in COMPARED)
                for r in cluster["runs"])
    out = {"runs": args.runs, "seed": args.seed, "address": address,
           "killed_worker_at_s": killed_at, "tasks_on_killed_worker": lost, "sweep_running_when_killed": still_running,
           "cluster": {"engine": cluster["engine"], "wall_s": cluster_wall, "summary": cluster["summary"],
                       "completed": sum("error" not in r for r in cluster["runs"])},
           "local": {"engine": local["engine"], "wall_s": local_wall, "summary": local["summary"]},
           "runs_equal_per_seed": equal, "compared_keys": list(COMPARED)}
    write("sweep_cluster", out)
    print(f"cluster: {out['cluster']['completed']}/{args.runs} runs completed, worker killed at {killed_at:.1f} s "
          f"holding {len(lost)} task(s) (sweep running: {still_running}); equal to the local run per seed: {equal}")


if __name__ == "__main__":
    main()
