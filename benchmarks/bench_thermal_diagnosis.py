"""Thermal identification and diagnosis on the simulated elbow (testbed): speed and detection.

1. Speed (medians of several runs): one-node identification of a 3-hour 1 Hz recording; diagnosis
   with the full candidate library of one 3-hour 1 Hz recording and of a pair; the peer in the same
   run is the one-node identification of the same recording (the ratio says how many fits'
   worth of work a diagnosis costs).
2. Detection on randomised recordings (testbed ``random_recording``: parameters, sensor noise
   0.05-0.2 °C, quantisation 0.1-0.5 °C, 0.2-2 Hz with jitter and gaps, effects none / friction /
   drive / both): per term, detection rate where the effect is present and observable (friction
   heating needs motion: biceps recordings), false-alarm rate where it is absent, and the rate of
   recordings with any false alarm.  casing_node is reported separately: the testbed always has a
   winding and a casing node, so accepting it is never false.
3. The same on randomised *pairs* (one static hold and one biceps curl of the same randomised plant,
   sensors and room, effects cycling none / friction / drive / both).  In one recording friction heat
   is indistinguishable from extra Joule heat (both are constant while the arm curls), so friction
   heating is observable only next to a static recording (seed report 4.4: compare a moving and a
   static experiment); singles measure it nonetheless.

    python benchmarks/bench_thermal_diagnosis.py [--seeds 40] [--pairs 24] [--repeats 5]
"""
from __future__ import annotations

import argparse
import time

import numpy as np

from _common import median_time, write
from thermo_ddp.diagnose.thermal import diagnose_thermal
from thermo_ddp.identify.thermal import identify_thermal
from thermo_ddp.testing.testbed import EFFECTS, PlantParameters, biceps, random_recording, static_4a
from thermo_ddp.testing.testbed.experiments import random_ambient, random_sensors

SPECIFIC = ("friction_heating", "drive_heating")
NEVER_TRUE = ("copper_resistance", "iron_losses")


def three_hour_recordings():
    """A 3-hour 1 Hz static_4a and a 3-hour 1 Hz biceps, both effects on."""
    params = PlantParameters().with_effects("both")
    return (static_4a(params=params, heating_s=6000.0, cooling_s=4500.0, sample_rate_hz=1.0).to_recording(),
            biceps(params=params, heating_s=2400.0, cooling_s=8100.0, sample_rate_hz=1.0).to_recording())


def bench_speed(repeats: int) -> dict:
    static, moving = three_hour_recordings()
    out = {"samples": [len(static), len(moving)], "duration_s": [float(static.time_s[-1]), float(moving.time_s[-1])]}
    out["identify_one_node_3h"] = median_time(lambda: identify_thermal(static, "one_node"), repeats)
    out["diagnose_one_3h"] = median_time(lambda: diagnose_thermal(static), max(repeats // 2, 1))
    out["diagnose_pair_3h"] = median_time(lambda: diagnose_thermal([static, moving]), max(repeats // 2, 1))
    out["diagnosis_over_identification"] = out["diagnose_one_3h"]["median_s"] / out["identify_one_node_3h"]["median_s"]
    diag = diagnose_thermal([static, moving])
    out["pair_missing_physics"] = diag.missing_physics
    for key in ("identify_one_node_3h", "diagnose_one_3h", "diagnose_pair_3h"):
        print(f"{key}: median {out[key]['median_s']:.2f} s")
    return out


def truth_terms(effects: str) -> set[str]:
    return {"none": set(), "friction": {"friction_heating"}, "drive": {"drive_heating"},
            "both": {"friction_heating", "drive_heating"}}[effects]


def random_pair(seed: int, effects: str):
    """A static hold and a biceps curl of one randomised plant (testbed parameter and sensor ranges)."""
    rng = np.random.default_rng(10_000 + seed)
    params = PlantParameters().randomised(rng).with_effects(effects)
    sensors, ambient = random_sensors(rng), random_ambient(rng)
    common = dict(params=params, sensors=sensors, ambient=ambient, idle_s=rng.uniform(60, 600))
    static = static_4a(heating_s=rng.uniform(1800, 3600), cooling_s=rng.uniform(1200, 2400),
                       current_a=rng.uniform(2.5, 4.0), seed=seed, **common)
    moving = biceps(heating_s=rng.uniform(900, 1800), cooling_s=rng.uniform(1200, 2400),
                    current_rms_a=rng.uniform(2.3, 2.8), seed=seed + 1, **common)
    return static, moving


def _row(seed, name, experiment, truth, recs) -> dict:
    present = {t for t, on in truth.parameters.effects.items() if on}
    t0 = time.perf_counter()
    diag = diagnose_thermal([r.to_recording() for r in recs])
    row = {"seed": seed, "name": name, "experiment": experiment, "present": sorted(present),
           "found": sorted(diag.missing_physics), "unexplained": len(diag.selection.final_localisation.mismatches),
           "rmse_before": diag.selection.baseline.fit.rmse, "rmse_after": diag.selection.final.fit.rmse,
           "sample_rate_hz": truth.sensors.sample_rate_hz, "noise_c": truth.sensors.temperature_noise_c,
           "quantum_c": truth.sensors.temperature_quantum_c, "seconds": time.perf_counter() - t0}
    print(f"{name:40s} present {row['present']} found {row['found']} ({row['seconds']:.1f} s)")
    return row


def bench_detection(seeds: range) -> dict:
    rows = []
    for seed in seeds:
        rec = random_recording(seed)
        rows.append(_row(seed, rec.name, rec.truth.experiment, rec.truth, [rec]))
    return {"recordings": rows, "rates": rates(rows)}


def bench_pairs(seeds: range) -> dict:
    rows = []
    for seed in seeds:
        effects = EFFECTS[seed % len(EFFECTS)]
        static, moving = random_pair(seed, effects)
        rows.append(_row(seed, f"pair-{seed}-{effects}", "biceps", static.truth, [static, moving]))
    return {"pairs": rows, "rates": rates(rows)}


def rates(rows: list[dict]) -> dict:
    out = {}
    for term in SPECIFIC:
        observable = [r for r in rows if term in r["present"] and (term != "friction_heating" or r["experiment"] == "biceps")]
        absent = [r for r in rows if term not in r["present"]]
        out[term] = {"detection_rate": _rate(observable, lambda r: term in r["found"]), "observable": len(observable),
                     "detection_rate_all_present": _rate([r for r in rows if term in r["present"]],
                                                         lambda r: term in r["found"]),
                     "false_alarm_rate": _rate(absent, lambda r: term in r["found"]), "absent": len(absent)}
    for term in NEVER_TRUE:
        out[term] = {"false_alarm_rate": _rate(rows, lambda r: term in r["found"]), "absent": len(rows)}
    out["casing_node_accept_rate"] = _rate(rows, lambda r: "casing_node" in r["found"])
    wrong = lambda r: bool(set(r["found"]) - set(r["present"]) - {"casing_node"})  # noqa: E731
    out["any_false_alarm_rate"] = _rate(rows, wrong)
    out["none_recordings_clean_rate"] = _rate([r for r in rows if not r["present"]], lambda r: not r["found"])
    return out


def _rate(rows, hit) -> float | None:
    return float(np.mean([hit(r) for r in rows])) if rows else None


def main():
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--seeds", type=int, default=40)
    parser.add_argument("--pairs", type=int, default=24)
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--skip-speed", action="store_true")
    args = parser.parse_args()
    payload = {"description": "thermal identification/diagnosis on the testbed: speed (median s) and "
                              "detection/false-alarm rates on randomised recordings"}
    if not args.skip_speed:
        payload["speed"] = bench_speed(args.repeats)
    payload["detection_single"] = bench_detection(range(args.seeds))
    payload["detection_pairs"] = bench_pairs(range(args.pairs))
    print("singles", payload["detection_single"]["rates"])
    print("pairs", payload["detection_pairs"]["rates"])
    write("thermal_diagnosis", payload)


if __name__ == "__main__":
    main()
