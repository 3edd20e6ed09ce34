"""``thermo-ddp identify --physics thermal``: recordings -> the identified parameter file.

A legacy file whose network measures only the recording's ``temperature_c`` is fitted by
:func:`~thermo_ddp.identify.thermal.identify_thermal` (and stays in its format); a general network file, or
recordings with further sensors that are nodes of the file's network, by
:func:`~thermo_ddp.identify.network_fit.fit_network` on the file's network, every sensor at once (a sensor the
network has no node for is left out and named: ``diagnose`` adds such nodes).  The file written carries
``[uncertainty]`` (95 % interval of every fitted value), ``[covariance]`` (their joint uncertainty) and
``[envelope]`` (what the recordings cover).
"""
from __future__ import annotations

from pathlib import Path
from typing import Sequence

from ..envelope import envelope_of
from ..model.parameters import JointParameters, ThermalParameters
from ..model.scope import LEARNED_SECTIONS
from ..recordings import read_recordings
from .network_fit import Free, fit_network
from .network import free_paths
from .thermal import identify_thermal, load_joint_parameters, parameter_file
from .thermal_data import ThermalSettings, split_at_gaps, thermal_grid

# Identification's search ranges of a network's values (the diagnosis narrows them further).
_CAPACITY = (1e-3, 1e7)
_RESISTANCE = (1e-4, 1e4)
_HEAT_W = 1e5


def _free(path: str) -> Free:
    name = path.rsplit(".", 1)[1]
    if name == "capacity_j_per_k":
        return Free(path, *_CAPACITY)
    if name == "resistance_k_per_w":
        return Free(path, *_RESISTANCE)
    if name == "speed_exponent":
        return Free(path, 1.0, 2.5, log=False)
    return Free(path, 0.0, 1.0 if ".split." in path else _HEAT_W, log=False)


def identify_network_files(params: JointParameters, recordings, settings: ThermalSettings) -> dict:
    """Every sensor at once on the file's network (module docstring)."""
    grids = [thermal_grid(part, params, settings) for rec in recordings for part in split_at_gaps(rec)[0]]
    spec = params.thermal.general
    fit = fit_network(params, spec, params.thermal.sensor_node, tuple(_free(p) for p in free_paths(spec)), grids)
    unused = sorted({n for g in grids for n in g.sensors} - set(spec.node_names))
    data = {k: v for k, v in params.to_dict().items() if k not in LEARNED_SECTIONS}
    data |= {"thermal": ThermalParameters("network", params.thermal.ambient_c, {}, fit.sensor, network=fit.spec,
                                         room_c=params.thermal.room_c).to_dict(),
             "uncertainty": fit.uncertainty(), "envelope": {k: list(v) for k, v in envelope_of(recordings).items()}}
    if fit.covariance() is not None:
        data["covariance"] = fit.covariance().to_dict()
    message = fit.message + (f"; sensors without a node in the network, not fitted: {', '.join(unused)} "
                             "(thermo-ddp diagnose adds them)" if unused else "")
    return {"physics": "thermal", "recordings": [g.name for g in grids], "model": "network",
            "rmse": fit.rmse(), "per_sensor": fit.per_sensor(), "noise_c": dict(fit.noise_c),
            "parameters": fit.values, "confidence_95": fit.uncertainty(), "success": fit.success,
            "status": fit.status, "message": message, "parameter_file": data if fit.success else None}


def identify_thermal_files(paths: Sequence[str | Path], model: str = "one_node", *,
                           parameters: JointParameters | str | Path | None = None, columns=None) -> dict:
    """CLI entry (``thermo-ddp identify --physics thermal``): CSV paths (any columns through the
    column map ``columns``) -> a JSON-ready dict with ``rows`` and the identified ``parameter_file``."""
    params = load_joint_parameters(parameters)
    recordings = read_recordings(paths, columns)
    recs = list(recordings.recordings)
    nodes = set(params.thermal.general.node_names)
    if params.thermal.model == "network" or any(set(rec.sensors) & nodes for rec in recs):
        return identify_network_files(params, recs, ThermalSettings(min_step_s=10.0, max_step_s=10.0)) | {
            "rows": recordings.rows}
    fit = identify_thermal(recs, model, parameters=params)
    return {"physics": "thermal", "recordings": list(fit.recordings), "rows": recordings.rows, **fit.summary(),
            "stderr": dict(fit.stderr), "confidence_95": {k: list(v) for k, v in fit.confidence.items()},
            "initial_offset_c": dict(fit.initial_offset_c), "n_samples": fit.n_samples,
            "success": fit.success, "status": fit.status, "message": fit.message,
            "parameter_file": parameter_file(params, fit, fit.recordings, envelope_of(recs)) if fit.success else None}
