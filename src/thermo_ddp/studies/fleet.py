"""Fleet diagnosis: one diagnosis per recording (one robot, one day), as Dask tasks on the sweep's engine,
and a table of which recordings show which missing physics."""
from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import Any, Mapping, Sequence

from .engine import EngineSettings, dask_client, engine_info, map_tasks


def diagnose_one(path: str, physics: str = "thermal", options: Mapping[str, Any] | None = None) -> dict[str, Any]:
    """The diagnosis dict of one recording: a pure function of the file and the options."""
    if physics == "mechanical":
        from ..diagnose.mechanical import diagnose_mechanical_files as run
    else:
        from ..diagnose.thermal import diagnose_thermal_files as run
    return run([path], **dict(options or {}))


@dataclasses.dataclass(frozen=True)
class FleetDiagnosis:
    """Every recording's diagnosis (or the error that stopped it), in the order given."""

    engine: dict[str, Any]
    physics: str
    recordings: tuple[str, ...]
    diagnoses: tuple[dict[str, Any], ...]

    @property
    def success(self) -> bool:
        return all(d.get("success", False) for d in self.diagnoses)

    @property
    def status(self) -> str:
        return "ok" if self.success else "some_failed"

    @property
    def message(self) -> str:
        failed = [r for r, d in zip(self.recordings, self.diagnoses) if not d.get("success", False)]
        return f"{len(self.recordings)} recordings diagnosed" + (
            f"; not successful: {', '.join(failed)}" if failed else "")

    def terms(self) -> dict[str, list[str]]:
        """Missing-physics term -> the recordings that show it."""
        found: dict[str, list[str]] = {}
        for rec, d in zip(self.recordings, self.diagnoses):
            for term in d.get("missing_physics", []):
                found.setdefault(term["term"], []).append(rec)
        return found

    def to_dict(self) -> dict[str, Any]:
        return {"success": self.success, "status": self.status, "message": self.message, "engine": self.engine,
                "physics": self.physics, "recordings": list(self.recordings),
                "diagnoses": [{"recording": r, **d} for r, d in zip(self.recordings, self.diagnoses)],
                "summary": {"terms": self.terms()}}

    def report(self) -> str:
        terms = sorted(self.terms())
        width = max([len(Path(r).name) for r in self.recordings] + [9])
        head = f"{'recording':<{width}}  {'status':<20}" + "".join(f"  {t:>18}" for t in terms)
        rows = [head, "-" * len(head)]
        for rec, d in zip(self.recordings, self.diagnoses):
            named = {t["term"] for t in d.get("missing_physics", [])}
            rows.append(f"{Path(rec).name:<{width}}  {d.get('status', 'error'):<20}"
                        + "".join(f"  {'missing' if t in named else '-':>18}" for t in terms))
        return "\n".join([f"fleet diagnosis ({self.physics}) on {self.engine['kind']}, "
                          f"{self.engine['workers']} workers: {self.message}", *rows])


def _error(message: str) -> dict[str, Any]:
    return {"success": False, "status": "error", "message": message, "missing_physics": []}


def diagnose_fleet(paths: Sequence[str | Path], physics: str = "thermal",
                   engine: EngineSettings = EngineSettings(), progress: bool | None = True,
                   **options: Any) -> FleetDiagnosis:
    """One diagnosis per recording on Dask; ``options`` go to each diagnosis unchanged."""
    recordings = tuple(str(p) for p in paths)
    with dask_client(engine) as client:
        info = engine_info(client).to_dict()
        outcomes = map_tasks(client, diagnose_one, recordings, progress=progress, desc="diagnose",
                             physics=physics, options=options)
    return FleetDiagnosis(info, physics, recordings,
                          tuple(o.value if o.success else _error(o.message) for o in outcomes))
