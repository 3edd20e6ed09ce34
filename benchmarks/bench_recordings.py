"""Reading and validating a long log: a generated one-hour 1 kHz recording (3.6 M rows).

Peers in the same run, on the same file:
1. the contract CSV (``time_s``, ``current_a``, ``temperature_c``, ``velocity``, ``ambient_c``) read and
   validated by ``read_csv`` (pandas' C parser) and by the reader it replaced (the csv-module reader of
   commit 60c21c4, loaded from git so both run in this process); rows per second, and their ratio;
2. the same samples in a logger's own layout (ISO 8601 stamps, i_d / i_q, rpm, Kelvin-free names) read
   through a column map (``read_mapped_csv``: date-time parsing, norm, scale);
3. ``validate_thermal`` of the loaded recording with the Paderborn parameter file on its 1 s grid.

    python benchmarks/bench_recordings.py [--rows 3600000] [--repeats 3] [--quick]
"""
from __future__ import annotations

import argparse
import subprocess
import sys
import tempfile
import types
from pathlib import Path

import numpy as np

from _common import median_time, write
from thermo_ddp.model.parameters import packaged_parameter_file
from thermo_ddp.recordings import column_map_from_dict, read_csv, read_mapped_csv
from thermo_ddp.validate import validate_thermal

BASE_COMMIT = "60c21c4"
RATE_HZ = 1000.0
LOGGER_MAP = {"time": {"column": "stamp"},
              "columns": {"temperature_c": "winding", "ambient_c": "coolant", "current_a": {"norm": ["i_d", "i_q"]},
                          "velocity": {"column": "speed_rpm", "scale": np.pi / 30}}}


def base_reader():
    """``read_csv`` of the recordings module at BASE_COMMIT (the csv-module reader), as a module."""
    here = Path(__file__).resolve().parent
    source = subprocess.run(["git", "show", f"{BASE_COMMIT}:src/thermo_ddp/recordings.py"], cwd=here,
                            capture_output=True, text=True, check=True).stdout
    module = types.ModuleType("thermo_ddp._recordings_base")
    module.__package__ = "thermo_ddp"
    sys.modules[module.__name__] = module  # dataclasses look their module up
    exec(compile(source, f"recordings.py@{BASE_COMMIT}", "exec"), module.__dict__)
    return module.read_csv


def signals(rows: int) -> dict[str, np.ndarray]:
    """A heat run: 150 A of |i_dq| at 5,000 rpm with noise, a winding warming 20 -> 100 degC."""
    rng = np.random.default_rng(0)
    t = np.arange(rows) / RATE_HZ
    i_d, i_q = -120.0 + rng.normal(0, 2, rows), 90.0 + rng.normal(0, 2, rows)
    return {"t": t, "i_d": i_d, "i_q": i_q, "rpm": 5000.0 + rng.normal(0, 5, rows),
            "winding": 20.0 + 80.0 * (1 - np.exp(-t / 900.0)) + rng.normal(0, 0.1, rows),
            "coolant": 18.0 + rng.normal(0, 0.05, rows)}


def write_files(folder: Path, s: dict[str, np.ndarray]) -> tuple[Path, Path]:
    contract, logger = folder / "contract.csv", folder / "logger.csv"
    np.savetxt(contract, np.column_stack([s["t"], np.hypot(s["i_d"], s["i_q"]), s["winding"], s["rpm"] * np.pi / 30,
                                          s["coolant"]]),
               delimiter=",", fmt="%.6f", header="time_s,current_a,temperature_c,velocity,ambient_c", comments="")
    stamps = (np.datetime64("2026-11-24T08:00:00.000") + (s["t"] * 1000).round().astype("timedelta64[ms]"))
    with logger.open("w") as f:
        f.write("stamp,i_d,i_q,speed_rpm,winding,coolant\n")
        for k in range(0, s["t"].size, 100_000):
            block = slice(k, k + 100_000)
            cols = [np.char.add(np.datetime_as_string(stamps[block], unit="ms"), "Z")]
            cols += [np.char.mod("%.6f", s[c][block]) for c in ("i_d", "i_q", "rpm", "winding", "coolant")]
            f.write("\n".join(",".join(r) for r in zip(*cols)) + "\n")
    return contract, logger


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rows", type=int, default=3_600_000)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--quick", action="store_true", help="one repeat")
    args = parser.parse_args()
    repeats = 1 if args.quick else args.repeats
    old_read_csv = base_reader()
    params = packaged_parameter_file("paderborn_pmsm")
    with tempfile.TemporaryDirectory() as tmp:
        contract, logger = write_files(Path(tmp), signals(args.rows))
        cmap = column_map_from_dict(LOGGER_MAP, "logger map")
        rec = read_csv(contract)
        old = old_read_csv(contract)
        for c in rec.columns:  # the peers read the same numbers
            np.testing.assert_array_equal(getattr(rec, c), getattr(old, c))
        mapped = read_mapped_csv(logger, cmap).recordings[0]
        np.testing.assert_allclose(mapped.current_a, rec.current_a, atol=2e-6)
        out = {"rows": args.rows, "rate_hz": RATE_HZ, "file_mb": {p.stem: p.stat().st_size / 1e6 for p in (contract, logger)},
               "pandas_read_csv": median_time(lambda: read_csv(contract), repeats),
               "csv_module_read_csv_at_" + BASE_COMMIT: median_time(lambda: old_read_csv(contract), repeats),
               "pandas_column_map_iso_stamps": median_time(lambda: read_mapped_csv(logger, cmap), repeats),
               "validate_1s_grid": median_time(lambda: validate_thermal([rec], params), repeats)}
    for key in ("pandas_read_csv", "csv_module_read_csv_at_" + BASE_COMMIT, "pandas_column_map_iso_stamps"):
        out[key]["rows_per_s"] = args.rows / out[key]["median_s"]
        print(f"{key}: median {out[key]['median_s']:.2f} s, {out[key]['rows_per_s'] / 1e6:.2f} M rows/s")
    out["speedup_pandas_over_csv_module"] = (out["csv_module_read_csv_at_" + BASE_COMMIT]["median_s"]
                                             / out["pandas_read_csv"]["median_s"])
    print(f"validate (1 s grid): median {out['validate_1s_grid']['median_s']:.2f} s; "
          f"pandas / csv module speed-up x{out['speedup_pandas_over_csv_module']:.1f}")
    write("recordings", out)


if __name__ == "__main__":
    main()
