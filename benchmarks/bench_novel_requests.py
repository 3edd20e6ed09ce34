"""Never-seen requests: whole plan_lift calls, DDP against IPOPT, in one run.

A user asks for a payload, limit and hold nobody asked for before. After one warm-up request (which fills a
fresh compiled-code cache), three random requests (payload 20-40 kg, limit 90-140 °C, hold 5-40 s; seeded)
are planned by DDP and by IPOPT, each a whole cold `plan_lift` call (problem, solver and any compilation
inside). Reported per request: wall time of each, the number of C compilations DDP needed (counted from
the codegen log), the achieved holds; and the median DDP / IPOPT wall ratio. The target of issue 15: nothing
compiled and DDP >= 5x IPOPT end to end.

    python benchmarks/bench_novel_requests.py [--requests 3] [--seed 0]
"""
from __future__ import annotations

import argparse
import logging
import os
import statistics
import tempfile
import time

from _common import write


class CompileCounter(logging.Handler):
    """Counts the codegen's 'compiling ...' records."""

    def __init__(self):
        super().__init__(logging.INFO)
        self.count = 0

    def emit(self, record):
        self.count += record.getMessage().startswith("compiling")


def timed_plan(plan_lift, counter: CompileCounter, request: dict, solver: str) -> dict:
    before = counter.count
    t0 = time.perf_counter()
    plan = plan_lift(request["payload_kg"], request["limit_c"], request["hold_s"], solver=solver)
    return {"wall_s": time.perf_counter() - t0, "compilations": counter.count - before, "status": plan.status,
            "achieved_hold_s": plan.achieved_hold_s, "solve_s": plan.solver["total_solve_s"],
            "solves": plan.solver["solves"]}


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--requests", type=int, default=3)
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args()
    os.environ["THERMO_DDP_CACHE"] = tempfile.mkdtemp(prefix="novel-requests-cache-")  # nothing seen before
    import numpy as np
    from thermo_ddp.tasks.lift import plan_lift

    counter = CompileCounter()
    codegen_log = logging.getLogger("thermo_ddp.codegen")
    codegen_log.setLevel(logging.INFO)
    codegen_log.addHandler(counter)
    warm_up = {"payload_kg": 40.0, "limit_c": 84.0, "hold_s": 30.0}
    warm = {s: timed_plan(plan_lift, counter, warm_up, s) for s in ("ddp", "ipopt")}
    rng = np.random.default_rng(args.seed)
    rows = []
    for _ in range(args.requests):
        request = {"payload_kg": round(float(rng.uniform(20, 40)), 1), "limit_c": round(float(rng.uniform(90, 140)), 1),
                   "hold_s": round(float(rng.uniform(5, 40)), 1)}
        ddp, ipopt = (timed_plan(plan_lift, counter, request, s) for s in ("ddp", "ipopt"))
        rows.append({**request, "ddp": ddp, "ipopt": ipopt, "ipopt_over_ddp_wall": ipopt["wall_s"] / ddp["wall_s"]})
        print(f"{request}: DDP {ddp['wall_s']:.2f} s ({ddp['compilations']} compilations, hold "
              f"{ddp['achieved_hold_s']:.1f} s), IPOPT {ipopt['wall_s']:.2f} s (hold {ipopt['achieved_hold_s']:.1f} s): "
              f"{rows[-1]['ipopt_over_ddp_wall']:.2f}x", flush=True)
    median = statistics.median(r["ipopt_over_ddp_wall"] for r in rows)
    write("novel_requests", {"warm_up": {**warm_up, **warm}, "requests": rows,
                             "median_ipopt_over_ddp_wall": median,
                             "ddp_compilations": sum(r["ddp"]["compilations"] for r in rows)})
    print(f"median IPOPT / DDP wall {median:.2f}x; DDP compiled {sum(r['ddp']['compilations'] for r in rows)} "
          f"times for {len(rows)} new requests")


if __name__ == "__main__":
    main()
