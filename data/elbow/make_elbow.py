"""Regenerate the simulated elbow recordings in this folder (deterministic: same seed, same bytes).

The robot is thermo-ddp's simulated elbow (``thermo_ddp.testing.testbed``) with its concealed physics on:
friction heating and drive heat (``PlantParameters().with_effects("both")``, the robot of ``thermo-ddp
loop``). It records two of the seed report's experiments, shortened: a static hold at about 3 A and the
biceps curl, each followed by cooling, with the room temperature logged. Values are written with 6
significant digits (the sensors' noise is far larger), so the files stay small.

    python data/elbow/make_elbow.py            # rewrites static_3a.csv and biceps.csv here
"""
from __future__ import annotations

import csv
import sys
from pathlib import Path

from thermo_ddp.testing.testbed import PlantParameters, biceps, static_3a

SEED = 0
COLUMNS = ("time_s", "current_a", "temperature_c", "velocity", "ambient_c")  # what the diagnosis reads
HERE = Path(__file__).resolve().parent


def recordings(seed: int = SEED):
    """The two experiments on the robot with friction heating and drive heat (the robot of ``loop``)."""
    robot = PlantParameters().with_effects("both")
    return (static_3a(params=robot, heating_s=1800.0, cooling_s=1800.0, loading_s=300.0, seed=seed),
            biceps(params=robot, heating_s=1200.0, cooling_s=1800.0, seed=seed))


def write(recording, path: Path) -> Path:
    """The contract CSV of ``recording``'s :data:`COLUMNS`, 6 significant digits."""
    with path.open("w", newline="") as handle:
        writer = csv.writer(handle, lineterminator="\n")
        writer.writerow(COLUMNS)
        for row in zip(*(recording.columns[c] for c in COLUMNS)):
            writer.writerow([f"{float(v):.6g}" for v in row])
    return path


def main(folder: Path = HERE) -> list[Path]:
    return [write(r, folder / f"{r.name}.csv") for r in recordings()]


if __name__ == "__main__":
    for written in main(Path(sys.argv[1]) if len(sys.argv) > 1 else HERE):
        print(f"wrote {written} ({written.stat().st_size / 1e3:.0f} kB)")
