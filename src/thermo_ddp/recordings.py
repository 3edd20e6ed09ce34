"""Recordings: one joint's measured signals on one time base, read from CSV or ROS 1/ROS 2 bags.

The CSV contract (docs/architecture.md): a header row, one sample per row, ``time_s`` (strictly
increasing seconds) and any of ``current_a``, ``temperature_c`` (the measured sensor), ``position``,
``velocity``, ``effort`` (ROS ``JointState`` meaning, SI units of the joint), ``ambient_c``,
``voltage_v``, ``room_c`` (a second boundary: the room around a liquid-cooled motor whose ``ambient_c`` is the
coolant), and more measured temperatures, one per network node: ``node_<name>_c``
(:attr:`Recording.sensors`).  Any other CSV is read through a column map (``--columns MAP.toml``,
:mod:`thermo_ddp.column_maps`): its own column names, date-time stamps, scales, a ``[sensors]`` table,
rows with empty cells and gaps that split it into segments.  Every problem with the input raises one
:class:`~thermo_ddp.errors.InputError` naming the file (or map), the column (or key) and the row.
Rows are counted as in the file: the header is row 1, the first sample row 2 (blank lines are not
counted).  For bags and in-memory arrays the row is the sample index (0-based) on the recording's
time base.  Bags are read by :mod:`thermo_ddp.bags` (a :class:`TopicMap` per joint).
"""
from __future__ import annotations

import dataclasses
import logging
import re
from pathlib import Path
from types import MappingProxyType
from typing import Mapping, Sequence

import numpy as np

from .errors import InputError
from .model.network_spec import check_node_name
from .model.parameters import BOUNDS

log = logging.getLogger(__name__)

SIGNALS = ("current_a", "temperature_c", "position", "velocity", "effort", "ambient_c", "voltage_v", "room_c")
COLUMNS = ("time_s",) + SIGNALS
_CELSIUS_COLUMNS = ("temperature_c", "ambient_c", "room_c")
KELVIN_SUSPECT_C = 200.0  # a motor casing or a room above 200 degC means the file holds kelvin
# Largest plausible magnitudes: the parameter catalogue's bound of the matching motor quantity.
PLAUSIBLE = {"current_a": "current_peak_a", "voltage_v": "bus_voltage_v", "velocity": "iron_loss_ref_speed_rad_s"}
_NODE_COLUMN = re.compile(r"node_(.+)_c")


def sensor_column(node: str) -> str:
    """The contract column of a node's measured temperature: ``node_<name>_c``."""
    return f"node_{node}_c"


def sensor_node(column: str) -> str | None:
    """The node a ``node_<name>_c`` column measures (None for another column)."""
    match = _NODE_COLUMN.fullmatch(column)
    return match.group(1) if match else None


def _check_signal(source: str, column: str, values: np.ndarray, row_of, kind: str | None = None) -> None:
    """Raise InputError on the first NaN/inf, kelvin-looking temperature or implausible magnitude in
    ``values`` (``kind``: the contract column, when ``column`` names it differently in messages)."""
    kind = kind or column
    bad = np.flatnonzero(~np.isfinite(values))
    if bad.size:
        raise InputError(source, column, values[bad[0]], "not a finite number", row=row_of(bad[0]))
    if kind in _CELSIUS_COLUMNS or sensor_node(kind):
        hot = np.flatnonzero((values > KELVIN_SUSPECT_C) | (values < -273.15))
        if hot.size:
            raise InputError(source, column, float(values[hot[0]]),
                             f"outside -273.15..{KELVIN_SUSPECT_C:g} degC: looks like kelvin or a wrong unit; "
                             "give degrees Celsius", row=row_of(hot[0]))
    if kind in PLAUSIBLE:
        bound = BOUNDS[PLAUSIBLE[kind]]
        big = np.flatnonzero(np.abs(values) > bound.high)
        if big.size:
            raise InputError(source, column, float(values[big[0]]), f"implausible: above {bound.high:g} {bound.unit} "
                             f"in magnitude ({bound.reason}); a wrong unit or scale?", row=row_of(big[0]))


def _check_time(source: str, time_s: np.ndarray, row_of, column: str = "time_s") -> None:
    _check_signal(source, column, time_s, row_of)
    step = np.diff(time_s)
    bad = np.flatnonzero(step <= 0)
    if bad.size:
        k = bad[0] + 1
        raise InputError(source, column, float(time_s[k]),
                         f"not strictly increasing (previous sample {float(time_s[k - 1])!r})", row=row_of(k))


def _frozen_array(source: str, column: str, value) -> np.ndarray:
    try:
        array = np.array(value, dtype=float)
    except (TypeError, ValueError) as err:
        raise InputError(source, column, "array", f"not numeric ({err})") from None
    array.setflags(write=False)
    return array


@dataclasses.dataclass(frozen=True)
class Recording:
    """One joint's recording on one time base (read-only numpy arrays, validated on creation).

    ``name`` identifies the recording in reports (usually the file name), ``source`` is the path
    it came from (used in error messages) and ``joint`` the joint name when known.  ``sensors``: more
    measured temperatures by network node (column ``node_<name>_c``); ``temperature_c`` is the one the
    parameter file's ``sensor`` node measures (:meth:`temperatures_by_node`).
    """

    name: str
    time_s: np.ndarray
    current_a: np.ndarray | None = None
    temperature_c: np.ndarray | None = None
    position: np.ndarray | None = None
    velocity: np.ndarray | None = None
    effort: np.ndarray | None = None
    ambient_c: np.ndarray | None = None
    voltage_v: np.ndarray | None = None
    room_c: np.ndarray | None = None
    joint: str | None = None
    source: str = ""
    row_offset: int = 0  # row of sample 0 in the source (2 for a CSV with a header), for messages
    sensors: Mapping[str, np.ndarray] = dataclasses.field(default_factory=dict)

    def __post_init__(self) -> None:
        src = self.source or self.name
        row_of = lambda k: int(k) + self.row_offset  # noqa: E731
        time_s = self._frozen("time_s")
        if time_s.ndim != 1 or time_s.size == 0:
            raise InputError(src, "time_s", f"shape {time_s.shape}", "expected a non-empty 1-D array")
        _check_time(src, time_s, row_of)
        columns = {c: self._frozen(c) for c in SIGNALS}
        sensors = {}
        for node, values in dict(self.sensors).items():
            column = sensor_column(check_node_name(src, "sensors", node))
            sensors[node] = columns[column] = _frozen_array(src, column, values)
        object.__setattr__(self, "sensors", MappingProxyType(sensors))
        for column, values in columns.items():
            if values is None:
                continue
            if values.shape != time_s.shape:
                raise InputError(src, column, f"shape {values.shape}", f"expected shape {time_s.shape} like time_s")
            _check_signal(src, column, values, row_of)

    def _frozen(self, column: str) -> np.ndarray | None:
        value = getattr(self, column)
        if value is None:
            return None
        array = _frozen_array(self.source or self.name, column, value)
        object.__setattr__(self, column, array)
        return array

    @property
    def columns(self) -> tuple[str, ...]:
        """Names of the contract's fixed columns present, in contract order (``time_s`` first)."""
        return tuple(c for c in COLUMNS if getattr(self, c) is not None)

    @property
    def sensor_columns(self) -> tuple[str, ...]:
        """The ``node_<name>_c`` columns present."""
        return tuple(sensor_column(n) for n in self.sensors)

    def temperatures_by_node(self, sensor_node: str) -> dict[str, np.ndarray]:
        """Every measured temperature by node: ``temperature_c`` as ``sensor_node`` (the parameter file's
        ``sensor``), and the ``sensors`` (which win when they also name ``sensor_node``)."""
        main = {} if self.temperature_c is None else {sensor_node: self.temperature_c}
        return main | dict(self.sensors)

    def take(self, index) -> "Recording":
        """The samples at ``index`` (a slice, boolean mask or indices; time stays increasing), every column
        and sensor included."""
        arrays = {c: getattr(self, c)[index] for c in self.columns}
        kept = np.arange(len(self))[index]
        offset = self.row_offset + (int(kept[0]) if kept.size else 0)
        return dataclasses.replace(self, row_offset=offset, sensors={n: v[index] for n, v in self.sensors.items()},
                                   **arrays)

    def require(self, *columns: str) -> None:
        """Raise InputError naming the first of ``columns`` this recording lacks."""
        present = (*self.columns, *self.sensor_columns)
        for column in columns:
            if column not in present:
                raise InputError(self.source or self.name, column, "missing",
                                 f"column required by this analysis; present: {', '.join(present)}")

    def __len__(self) -> int:
        return int(self.time_s.size)

    def to_csv(self, path: str | Path) -> Path:
        """Write the contract CSV (present columns only); ``read_csv`` reads it back exactly."""
        path = Path(path)
        columns = self.columns
        data = np.column_stack([getattr(self, c) for c in columns] + list(self.sensors.values()))
        np.savetxt(path, data, delimiter=",", header=",".join(columns + self.sensor_columns), comments="", fmt="%.17g")
        return path


@dataclasses.dataclass(frozen=True)
class RecordingSet:
    """Recordings read from files, one per segment, with the rows used and skipped (``rows``:
    the contract's ``{"used", "skipped", "segments"}``)."""

    recordings: tuple[Recording, ...]
    used: int
    skipped: int = 0

    @property
    def rows(self) -> dict[str, int]:
        return {"used": self.used, "skipped": self.skipped, "segments": len(self.recordings)}

    def __add__(self, other: "RecordingSet") -> "RecordingSet":
        return RecordingSet(self.recordings + other.recordings, self.used + other.used, self.skipped + other.skipped)


def read_recordings(paths: Sequence[str | Path], columns: ColumnMap | str | Path | None = None) -> RecordingSet:
    """CSV files (contract columns, or any columns through ``columns``, a map or its TOML path) ->
    their recordings, one per segment, and the rows used and skipped."""
    cmap = load_column_map(columns) if isinstance(columns, (str, Path)) else columns
    out = RecordingSet((), 0)
    for path in paths:
        if cmap is None:
            rec = read_recording(path)
            out += RecordingSet((rec,), len(rec))
        else:
            if Path(path).suffix.lower() != ".csv":
                raise InputError(str(path), "file", Path(path).suffix or "directory", "a column map reads .csv files")
            out += read_mapped_csv(path, cmap)
    return out

def resample(recording: Recording, time_s: Sequence[float] | np.ndarray) -> Recording:
    """Linear interpolation of every column onto ``time_s`` (which must lie inside the recording)."""
    time_s = np.asarray(time_s, dtype=float)
    src = recording.source or recording.name
    _check_time(src, time_s, int)
    lo, hi = recording.time_s[0], recording.time_s[-1]
    if time_s[0] < lo or time_s[-1] > hi:
        raise InputError(src, "time_s", f"{time_s[0]:g}..{time_s[-1]:g}",
                         f"resampling outside the recorded span {lo:g}..{hi:g} s")
    columns = {c: np.interp(time_s, recording.time_s, getattr(recording, c))
               for c in SIGNALS if getattr(recording, c) is not None}
    sensors = {n: np.interp(time_s, recording.time_s, v) for n, v in recording.sensors.items()}
    return dataclasses.replace(recording, time_s=time_s, row_offset=0, sensors=sensors, **columns)


def common_time(recordings: Sequence[Recording], dt_s: float | None = None) -> np.ndarray:
    """A uniform time base over the span all ``recordings`` share (step: the coarsest median step)."""
    lo = max(r.time_s[0] for r in recordings)
    hi = min(r.time_s[-1] for r in recordings)
    if hi <= lo:
        raise InputError(", ".join(r.name for r in recordings), "time_s", f"{lo:g}..{hi:g}", "recordings do not overlap")
    step = dt_s or max(float(np.median(np.diff(r.time_s))) for r in recordings if len(r) > 1)
    return lo + step * np.arange(int(np.floor((hi - lo) / step + 1e-9)) + 1)


def read_recording(path: str | Path, topic_map: TopicMap | None = None) -> Recording:
    """A CSV file, or a bag (``.bag`` file or ROS 2 bag directory) when ``topic_map`` is given."""
    path = Path(path)
    if path.suffix.lower() == ".csv":
        return read_csv(path)
    if topic_map is None:
        raise InputError(str(path), "file", path.suffix or "directory", "not a .csv file; a bag needs a topic map")
    return read_bag(path, topic_map)


def as_recordings(recordings, source: str) -> list[Recording]:
    """Recording objects or paths (one or a sequence) -> validated, distinctly named recordings."""
    recordings = [recordings] if isinstance(recordings, (Recording, str, Path)) else list(recordings)
    recordings = [r if isinstance(r, Recording) else read_recording(r) for r in recordings]
    if not recordings:
        raise InputError(source, "recordings", "none", "give at least one recording")
    names = [r.name for r in recordings]
    if len(set(names)) != len(names):
        raise InputError(source, "recordings", ", ".join(names), "recording names must be distinct")
    return recordings


# The readers of column maps and bags, re-exported: one import for every recording (they import this module).
from .column_maps import (ColumnMap, Source, column_map_from_dict, load_column_map, read_csv,  # noqa: E402,F401
                          read_mapped_csv)
from .bags import TopicMap, read_bag, read_bag_joints  # noqa: E402,F401
