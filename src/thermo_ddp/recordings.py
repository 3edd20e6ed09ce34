"""Recordings: one joint's measured signals on one time base, read from CSV or ROS 1/ROS 2 bags.

The CSV contract (docs/architecture.md): a header row, one sample per row, ``time_s`` (strictly
increasing seconds) and any of ``current_a``, ``temperature_c`` (the casing sensor), ``position``,
``velocity``, ``effort`` (ROS ``JointState`` meaning, SI units of the joint), ``ambient_c``,
``voltage_v``.  Any other CSV is read through a :class:`ColumnMap` (``--columns MAP.toml``): its own
column names, date-time stamps, scales, rows with empty cells and gaps that split it into segments.
CSV files are parsed by pandas' C reader.  Every problem with the input raises one
:class:`~thermo_ddp.errors.InputError` naming the file (or map), the column (or key) and the row.
Rows are counted as in the file: the header is row 1, the first sample row 2 (blank lines are not
counted).  For bags and in-memory arrays the row is the sample
index (0-based) on the recording's time base.

A bag is read through a :class:`TopicMap` (one joint).  Several joints of one bag are read in
a single pass with :func:`read_bag_joints`.
"""
from __future__ import annotations

import csv
import dataclasses
import logging
import math
import tomllib
import warnings
from pathlib import Path
from typing import Iterable, Mapping, Sequence

import numpy as np
import pandas as pd

from .errors import InputError
from .model.parameters import BOUNDS

log = logging.getLogger(__name__)

SIGNALS = ("current_a", "temperature_c", "position", "velocity", "effort", "ambient_c", "voltage_v")
COLUMNS = ("time_s",) + SIGNALS
_CELSIUS_COLUMNS = ("temperature_c", "ambient_c")
KELVIN_SUSPECT_C = 200.0  # a motor casing or a room above 200 degC means the file holds kelvin
# Largest plausible magnitudes: the parameter catalogue's bound of the matching motor quantity.
PLAUSIBLE = {"current_a": "current_peak_a", "voltage_v": "bus_voltage_v", "velocity": "iron_loss_ref_speed_rad_s"}
JOINT_STATE_FIELDS = ("position", "velocity", "effort")
_JOINT_STATE = "sensor_msgs/msg/JointState"
_SCALAR_TYPES = {"sensor_msgs/msg/Temperature": "temperature", "std_msgs/msg/Float64": "data",
                 "std_msgs/msg/Float32": "data"}


def _check_signal(source: str, column: str, values: np.ndarray, row_of, kind: str | None = None) -> None:
    """Raise InputError on the first NaN/inf, kelvin-looking temperature or implausible magnitude in
    ``values`` (``kind``: the contract column, when ``column`` names it differently in messages)."""
    kind = kind or column
    bad = np.flatnonzero(~np.isfinite(values))
    if bad.size:
        raise InputError(source, column, values[bad[0]], "not a finite number", row=row_of(bad[0]))
    if kind in _CELSIUS_COLUMNS:
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


@dataclasses.dataclass(frozen=True)
class Recording:
    """One joint's recording on one time base (read-only numpy arrays, validated on creation).

    ``name`` identifies the recording in reports (usually the file name), ``source`` is the path
    it came from (used in error messages) and ``joint`` the joint name when known.
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
    joint: str | None = None
    source: str = ""
    row_offset: int = 0  # row of sample 0 in the source (2 for a CSV with a header), for messages

    def __post_init__(self) -> None:
        src = self.source or self.name
        row_of = lambda k: int(k) + self.row_offset  # noqa: E731
        time_s = self._frozen("time_s")
        if time_s.ndim != 1 or time_s.size == 0:
            raise InputError(src, "time_s", f"shape {time_s.shape}", "expected a non-empty 1-D array")
        _check_time(src, time_s, row_of)
        for column in SIGNALS:
            values = self._frozen(column)
            if values is None:
                continue
            if values.shape != time_s.shape:
                raise InputError(src, column, f"shape {values.shape}", f"expected shape {time_s.shape} like time_s")
            _check_signal(src, column, values, row_of)

    def _frozen(self, column: str) -> np.ndarray | None:
        value = getattr(self, column)
        if value is None:
            return None
        try:
            array = np.array(value, dtype=float)
        except (TypeError, ValueError) as err:
            raise InputError(self.source or self.name, column, "array", f"not numeric ({err})") from None
        array.setflags(write=False)
        object.__setattr__(self, column, array)
        return array

    @property
    def columns(self) -> tuple[str, ...]:
        """Names of the columns present, in contract order (``time_s`` first)."""
        return tuple(c for c in COLUMNS if getattr(self, c) is not None)

    def require(self, *columns: str) -> None:
        """Raise InputError naming the first of ``columns`` this recording lacks."""
        for column in columns:
            if getattr(self, column, None) is None:
                raise InputError(self.source or self.name, column, "missing",
                                 f"column required by this analysis; present: {', '.join(self.columns)}")

    def __len__(self) -> int:
        return int(self.time_s.size)

    def to_csv(self, path: str | Path) -> Path:
        """Write the contract CSV (present columns only); ``read_csv`` reads it back exactly."""
        path = Path(path)
        columns = self.columns
        data = np.column_stack([getattr(self, c) for c in columns])
        np.savetxt(path, data, delimiter=",", header=",".join(columns), comments="", fmt="%.17g")
        return path


# ----------------------------------------------------------------------------- column maps
@dataclasses.dataclass(frozen=True)
class Source:
    """One contract column from the CSV's own columns: ``value * scale + offset``, where ``value`` is
    the single column, or the Euclidean norm of several (``norm``, e.g. the d and q currents)."""

    columns: tuple[str, ...]
    norm: bool = False
    scale: float = 1.0
    offset: float = 0.0

    def label(self, contract: str) -> str:
        """How errors name the column: ``temperature_c``, or ``temperature_c (from stator_winding)``."""
        if not self.norm and self.columns == (contract,) and (self.scale, self.offset) == (1.0, 0.0):
            return contract
        return f"{contract} (from {'norm of ' if self.norm else ''}{', '.join(self.columns)})"

    def values(self, table: Mapping[str, np.ndarray]) -> np.ndarray:
        parts = [table[c] for c in self.columns]
        value = np.sqrt(sum(p * p for p in parts)) if self.norm else parts[0]
        return value * self.scale + self.offset


_MAP_KEYS = {"time": ("column", "step_s"), "columns": SIGNALS, "rows": ("skip_incomplete", "split_gaps_s")}
_SOURCE_KEYS = ("column", "norm", "scale", "offset")
GAP_FACTOR = 10.0  # default split: a gap longer than 10 median sample steps


@dataclasses.dataclass(frozen=True)
class ColumnMap:
    """How a CSV's own columns become the recording contract (docs/architecture.md, "Column map").

    Time: ``time_column`` (seconds, or ISO 8601 date-times, quoted or not; date-times count from the
    first sample) or a fixed ``step_s``.  ``skip_incomplete``: drop rows with an empty cell in a mapped
    column (counted) instead of refusing the file.  ``split_gaps_s``: a longer gap between samples
    splits the file into segments (None: ``GAP_FACTOR`` x the median step; inf: never)."""

    source: str
    columns: Mapping[str, Source]
    time_column: str | None = "time_s"
    step_s: float | None = None
    skip_incomplete: bool = False
    split_gaps_s: float | None = None

    @property
    def source_columns(self) -> tuple[str, ...]:
        """The CSV columns the map reads (time first), each once."""
        names = ([self.time_column] if self.time_column else []) + [c for s in self.columns.values() for c in s.columns]
        return tuple(dict.fromkeys(names))

    def check_writable(self, available: Sequence[str]) -> None:
        """Refuse, before any work, a map that a logger of the contract columns ``available`` cannot write
        a CSV for (:meth:`write_csv`): a fixed step instead of a time column, a norm (not invertible), a
        zero scale, a contract column the logger lacks, or two columns written under one name."""
        if self.time_column is None:
            raise _map_error(self.source, "time.step_s", self.step_s, "a logger with time stamps writes a time "
                             "column: give [time] column")
        names = [self.time_column]
        for contract, src in self.columns.items():
            key = f"columns.{contract}"
            if contract not in available:
                raise _map_error(self.source, key, src.columns[0], f"not logged here; logged: {', '.join(available)}")
            if src.norm:
                raise _map_error(self.source, f"{key}.norm", list(src.columns), "a norm cannot be written back")
            if src.scale == 0:
                raise _map_error(self.source, f"{key}.scale", src.scale, "must not be 0 to be written back")
            if src.columns[0] in names:
                raise _map_error(self.source, key, src.columns[0], "another mapped column has this name")
            names.append(src.columns[0])

    def write_csv(self, path: str | Path, signals: Mapping[str, np.ndarray]) -> Path:
        """Write the contract ``signals`` (``time_s`` and every mapped column) as the CSV this map reads
        back: each under its source name, as ``(value - offset) / scale``; time in seconds."""
        table = {self.time_column: np.asarray(signals["time_s"], float)}
        for contract, src in self.columns.items():
            table[src.columns[0]] = (np.asarray(signals[contract], float) - src.offset) / src.scale
        pd.DataFrame(table).to_csv(path, index=False, float_format="%.17g")
        return Path(path)

    @classmethod
    def contract(cls, header: Sequence[str], source: str) -> "ColumnMap":
        """The identity map of a contract CSV (never split: the recording is one piece)."""
        return cls(source, {c: Source((c,)) for c in header if c != "time_s"}, split_gaps_s=math.inf)


def _map_error(source: str, key: str, value, problem: str) -> InputError:
    return InputError(source, key, value if isinstance(value, str) else repr(value), problem)


def _map_number(source: str, key: str, value, positive: bool = False) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise _map_error(source, key, value, "expected a finite number")
    if positive and value <= 0:
        raise _map_error(source, key, value, "must be > 0")
    return float(value)


def _map_section(source: str, data: Mapping, section: str) -> Mapping:
    sec = data.get(section, {})
    if not isinstance(sec, Mapping):
        raise _map_error(source, f"[{section}]", sec, "expected a table")
    for key in sec:
        if key not in _MAP_KEYS[section]:
            raise _map_error(source, f"{section}.{key}", sec[key], f"unknown key; known: {', '.join(_MAP_KEYS[section])}")
    return sec


def _map_source(source: str, key: str, spec) -> Source:
    if isinstance(spec, str):
        spec = {"column": spec}
    if not isinstance(spec, Mapping):
        raise _map_error(source, key, spec, 'expected "column", { column = ... } or { norm = [...] }')
    for k in spec:
        if k not in _SOURCE_KEYS:
            raise _map_error(source, f"{key}.{k}", spec[k], f"unknown key; known: {', '.join(_SOURCE_KEYS)}")
    if ("column" in spec) == ("norm" in spec):
        raise _map_error(source, key, dict(spec), "give exactly one of column, norm")
    names = [spec["column"]] if "column" in spec else spec["norm"]
    if not isinstance(names, list) or not names or not all(isinstance(n, str) and n for n in names):
        raise _map_error(source, f"{key}.{'column' if 'column' in spec else 'norm'}", names,
                         "expected a column name (norm: a list of names)")
    return Source(tuple(names), "norm" in spec, *(_map_number(source, f"{key}.{k}", spec.get(k, d))
                                                   for k, d in (("scale", 1.0), ("offset", 0.0))))


def column_map_from_dict(data: Mapping, source: str = "<column map>") -> ColumnMap:
    """Validate a parsed column map; errors name the map and the key."""
    for section in data:
        if section not in _MAP_KEYS:
            raise _map_error(source, f"[{section}]", "section", f"unknown section; known: {', '.join(_MAP_KEYS)}")
    time, cols, rows = (_map_section(source, data, s) for s in _MAP_KEYS)
    if ("column" in time) == ("step_s" in time):
        raise _map_error(source, "[time]", dict(time), "give exactly one of column, step_s")
    column = time.get("column")
    if column is not None and (not isinstance(column, str) or not column):
        raise _map_error(source, "time.column", column, "expected a column name")
    step = _map_number(source, "time.step_s", time["step_s"], positive=True) if "step_s" in time else None
    if not cols:
        raise _map_error(source, "[columns]", "empty", f"map at least one of {', '.join(SIGNALS)}")
    skip = rows.get("skip_incomplete", False)
    if not isinstance(skip, bool):
        raise _map_error(source, "rows.skip_incomplete", skip, "expected true or false")
    split = rows.get("split_gaps_s")
    split = None if split is None else _map_number(source, "rows.split_gaps_s", split, positive=True)
    return ColumnMap(source, {k: _map_source(source, f"columns.{k}", v) for k, v in cols.items()},
                     column, step, skip, split)


def load_column_map(path: str | Path) -> ColumnMap:
    """Read and validate a column map (TOML, ``--columns MAP.toml``)."""
    source = str(path)
    try:
        data = tomllib.loads(Path(path).read_text())
    except (OSError, UnicodeDecodeError) as err:
        raise InputError(source, "file", "unreadable", f"cannot read the column map ({err})") from None
    except tomllib.TOMLDecodeError as err:
        raise InputError(source, "TOML", "<file>", f"not valid TOML ({err})") from None
    return column_map_from_dict(data, source)


# ----------------------------------------------------------------------------- CSV (pandas)
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


def _header(source: str, path: Path) -> list[str]:
    try:
        with path.open(newline="") as handle:
            first = next(csv.reader(handle), [])
    except (OSError, UnicodeDecodeError) as err:
        raise InputError(source, "file", "unreadable", str(err)) from None
    header = [cell.strip() for cell in first]
    if not any(header):
        raise InputError(source, "file", "empty", "no header row and no samples")
    if len(set(header)) != len(header):
        raise InputError(source, "header", ",".join(header), "a column appears twice", row=1)
    return header


def _table(source: str, path: Path, width: int):
    """The CSV as a table of numbers or text (pandas' C parser; no cell is read as missing).  Every
    column is read: a row with more cells than the header is refused, never silently cut."""
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("error", pd.errors.ParserWarning)
            return pd.read_csv(path, na_filter=False, index_col=False, skipinitialspace=True, engine="c",
                               encoding_errors="strict")
    except (pd.errors.ParserError, pd.errors.ParserWarning):
        row, cells = _long_row(path, width)
        raise InputError(source, "row", f"{cells} cells", f"the header has {width}", row=row) from None
    except (OSError, UnicodeDecodeError, ValueError) as err:
        raise InputError(source, "file", "unreadable", str(err).strip().splitlines()[0]) from None


def _long_row(path: Path, width: int) -> tuple[int | None, int]:
    """(row, cells) of the first row with more cells than the header (only called on a parser error)."""
    with path.open(newline="") as handle:
        for row, cells in enumerate((c for c in csv.reader(handle) if c), start=1):
            if len(cells) > width:
                return row, len(cells)
    return None, width


def _cells(series) -> np.ndarray:
    """A column as floats (a numeric column) or as stripped text without quotes (logs quote time
    stamps, sometimes several times); numpy's vectorised string functions."""
    if pd.api.types.is_numeric_dtype(series.dtype) and not pd.api.types.is_bool_dtype(series.dtype):
        return series.to_numpy(dtype=float)
    return np.char.strip(np.char.strip(np.char.strip(series.to_numpy(dtype=str)), '"'))


def _is_text(cells: np.ndarray) -> bool:
    return cells.dtype.kind == "U"


def _numbers(source: str, column: str, cells: np.ndarray, rows: np.ndarray) -> np.ndarray:
    """A column as floats; InputError naming the first cell that is not a number."""
    if not _is_text(cells):
        return cells
    values = pd.to_numeric(cells, errors="coerce").astype(float)
    bad = np.flatnonzero(np.isnan(values) & (np.char.lower(cells) != "nan"))  # nan: the finiteness check names it
    if bad.size:
        raise InputError(source, column, str(cells[bad[0]]), "not a number", row=int(rows[bad[0]]))
    return values


def _time_s(source: str, cmap: ColumnMap, cells: Mapping[str, np.ndarray], rows: np.ndarray) -> np.ndarray:
    """Seconds: from ``step_s`` and the file row, a column of seconds, or ISO 8601 date-times
    (counted from the first kept sample; the first cell decides which)."""
    if cmap.step_s is not None:
        return cmap.step_s * (rows - rows[0])
    text = cells[cmap.time_column]
    if not _is_text(text) or not np.isnan(pd.to_numeric(text[:1], errors="coerce").astype(float)[0]):
        return _numbers(source, cmap.time_column, text, rows)
    stamps = pd.to_datetime(pd.Series(text), format="ISO8601", utc=True, errors="coerce")
    bad = np.flatnonzero(stamps.isna().to_numpy())
    if bad.size:
        raise InputError(source, cmap.time_column, str(text[bad[0]]), "neither seconds nor an ISO 8601 date-time",
                         row=int(rows[bad[0]]))
    return (stamps - stamps.iloc[0]).dt.total_seconds().to_numpy(dtype=float)


def _split(time_s: np.ndarray, split_gaps_s: float | None) -> list[tuple[int, int]]:
    """[start, stop) of the segments between gaps longer than ``split_gaps_s``."""
    dt = np.diff(time_s)
    limit = GAP_FACTOR * float(np.median(dt)) if split_gaps_s is None and dt.size else split_gaps_s
    cuts = [0, *(np.flatnonzero(dt > limit) + 1 if dt.size and limit is not None else ()), time_s.size]
    return list(zip(cuts[:-1], cuts[1:]))


def read_mapped_csv(path: str | Path, columns: ColumnMap, name: str | None = None) -> RecordingSet:
    """Read any CSV through a column map: one :class:`Recording` per segment (named ``name#k`` when
    the file splits), validated with the CSV's own row numbers (header row 1)."""
    path = Path(path)
    source, name = str(path), name or path.name
    header = _header(source, path)
    for column in columns.source_columns:
        if column not in header:
            raise InputError(source, column, "missing", f"no such column (wanted by {columns.source}); "
                             f"the CSV has: {', '.join(header)}", row=1)
    frame = _table(source, path, len(header))
    frame.columns = header  # stripped names (logs have trailing spaces)
    if frame.empty:
        raise InputError(source, "file", "header only", "no samples after the header", row=2)
    rows = np.arange(len(frame)) + 2
    cells = {c: _cells(frame[c]) for c in columns.source_columns}
    empty = {c: v == "" for c, v in cells.items() if _is_text(v)}
    incomplete = np.logical_or.reduce([np.zeros(rows.size, dtype=bool), *empty.values()])
    if incomplete.any() and not columns.skip_incomplete:
        k = int(np.argmax(incomplete))
        column = next(c for c, e in empty.items() if e[k])
        raise InputError(source, column, "", "empty cell (set [rows] skip_incomplete = true in a column map "
                         "to drop such rows)", row=int(rows[k]))
    keep = ~incomplete
    if not keep.any():
        raise InputError(source, "file", "no complete row", "every row has an empty cell in a mapped column")
    cells, rows = {c: v[keep] for c, v in cells.items()}, rows[keep]
    time_s = _time_s(source, columns, cells, rows)
    table = {c: _numbers(source, c, v, rows) for c, v in cells.items() if c != columns.time_column}
    signals = {c: s.values(table) for c, s in columns.columns.items()}
    row_of = lambda k: int(rows[k])  # noqa: E731
    _check_time(source, time_s, row_of, columns.time_column or "time_s")
    for column, values in signals.items():
        _check_signal(source, columns.columns[column].label(column), values, row_of, kind=column)
    segments = _split(time_s, columns.split_gaps_s)
    recordings = tuple(Recording(name=name if len(segments) == 1 else f"{name}#{k + 1}", source=source,
                                 row_offset=int(rows[a]), time_s=time_s[a:b], **{c: v[a:b] for c, v in signals.items()})
                       for k, (a, b) in enumerate(segments))
    return RecordingSet(recordings, int(keep.sum()), int(incomplete.sum()))


def read_csv(path: str | Path, name: str | None = None) -> Recording:
    """Read a contract CSV (columns named as in the contract) into one :class:`Recording`."""
    path = Path(path)
    source = str(path)
    header = _header(source, path)
    for column in header:
        if column not in COLUMNS:
            raise InputError(source, column or "(empty header cell)", "column",
                             f"unknown column; the contract columns are {', '.join(COLUMNS)} "
                             "(other names: give a column map)", row=1)
    if "time_s" not in header:
        raise InputError(source, "time_s", "missing", "every recording needs a time_s column", row=1)
    return read_mapped_csv(path, ColumnMap.contract(header, source), name).recordings[0]


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
    return dataclasses.replace(recording, time_s=time_s, row_offset=0, **columns)


def common_time(recordings: Sequence[Recording], dt_s: float | None = None) -> np.ndarray:
    """A uniform time base over the span all ``recordings`` share (step: the coarsest median step)."""
    lo = max(r.time_s[0] for r in recordings)
    hi = min(r.time_s[-1] for r in recordings)
    if hi <= lo:
        raise InputError(", ".join(r.name for r in recordings), "time_s", f"{lo:g}..{hi:g}", "recordings do not overlap")
    step = dt_s or max(float(np.median(np.diff(r.time_s))) for r in recordings if len(r) > 1)
    return lo + step * np.arange(int(np.floor((hi - lo) / step + 1e-9)) + 1)


@dataclasses.dataclass(frozen=True)
class TopicMap:
    """Where one joint's signals live in a bag.

    ``joint_states``: a ``sensor_msgs/JointState`` topic; ``position``/``velocity``/``effort`` of
    the entry named ``joint`` are read from it.  ``temperature`` and ``current``: topics of type
    ``sensor_msgs/Temperature``, ``std_msgs/Float64`` (or ``Float32``), or ``JointState`` (then the
    entry ``joint`` of the field ``temperature_field`` / ``current_field`` is read).  Every topic
    is optional, but at least one must be given; signals are interpolated onto the time base of
    the first topic given (joint_states, else temperature, else current), cut to the span all
    topics share.  Time is the message header stamp when the message has one, else the bag time,
    and the recording starts at 0 s.
    """

    joint: str
    joint_states: str | None = "/joint_states"
    temperature: str | None = None
    current: str | None = None
    temperature_field: str = "effort"
    current_field: str = "effort"

    def __post_init__(self) -> None:
        if not self.joint:
            raise InputError("topic map", "joint", self.joint, "a joint name is required")
        if not (self.joint_states or self.temperature or self.current):
            raise InputError("topic map", "topics", "none", "give at least one of joint_states, temperature, current")
        for key in ("temperature_field", "current_field"):
            if getattr(self, key) not in JOINT_STATE_FIELDS:
                raise InputError("topic map", key, getattr(self, key), f"expected one of {', '.join(JOINT_STATE_FIELDS)}")

    def topics(self) -> tuple[str, ...]:
        return tuple(t for t in (self.joint_states, self.temperature, self.current) if t)


def _stamp(message, bag_time_ns: int) -> float:
    header = getattr(message, "header", None)
    if header is not None and (header.stamp.sec or header.stamp.nanosec):
        return header.stamp.sec + 1e-9 * header.stamp.nanosec
    return 1e-9 * bag_time_ns


def _read_topics(path: Path, topics: Iterable[str]) -> tuple[dict[str, str], dict[str, list]]:
    """Deserialise every message of ``topics``: ({topic: msgtype}, {topic: [(t, message)]})."""
    from rosbags.highlevel import AnyReader

    wanted = set(topics)
    source = str(path)
    if not path.exists():
        raise InputError(source, "file", "missing", "no such bag file or directory")
    try:
        with AnyReader([path]) as reader:
            present = {c.topic: c.msgtype for c in reader.connections}
            for topic in sorted(wanted):
                if topic not in present:
                    have = ", ".join(f"{t} ({m})" for t, m in sorted(present.items())) or "none"
                    raise InputError(source, "topic", topic, f"not in the bag; the bag has: {have}")
            messages: dict[str, list] = {t: [] for t in wanted}
            connections = [c for c in reader.connections if c.topic in wanted]
            for connection, bag_ns, raw in reader.messages(connections=connections):
                message = reader.deserialize(raw, connection.msgtype)
                messages[connection.topic].append((_stamp(message, bag_ns), message))
    except InputError:
        raise
    except Exception as err:  # rosbags raises several error types for damaged files
        raise InputError(source, "file", "unreadable bag", f"{type(err).__name__}: {err} (truncated or not a bag?)") from None
    for topic, items in messages.items():
        if not items:
            raise InputError(source, "topic", topic, "the topic has no messages")
    return present, messages


def _joint_series(source: str, topic: str, items: list, joint: str, field: str) -> tuple[np.ndarray, np.ndarray]:
    times, values = [], []
    for k, (t, message) in enumerate(items):
        names = list(message.name)
        if joint not in names:
            raise InputError(source, f"{topic} name", joint,
                             f"joint not in the JointState message; it has: {', '.join(names)}", row=k)
        array = getattr(message, field)
        index = names.index(joint)
        if len(array) <= index:
            raise InputError(source, f"{topic} {field}", f"{len(array)} values",
                             f"no {field} for {joint}", row=k)
        times.append(t)
        values.append(float(array[index]))
    return np.asarray(times), np.asarray(values)


def _scalar_series(source: str, topic: str, msgtype: str, items: list, joint: str, field: str):
    if msgtype == _JOINT_STATE:
        return _joint_series(source, topic, items, joint, field)
    attribute = _SCALAR_TYPES.get(msgtype)
    if attribute is None:
        raise InputError(source, "topic", topic, f"type {msgtype} not supported; use "
                         f"{', '.join(sorted(_SCALAR_TYPES))} or {_JOINT_STATE}")
    return (np.asarray([t for t, _ in items]),
            np.asarray([float(getattr(m, attribute)) for _, m in items]))


def _unique_increasing(source: str, topic: str, times: np.ndarray, values: np.ndarray):
    """Sort by time and drop repeated stamps (bags record re-sent messages); reject nothing else."""
    order = np.argsort(times, kind="stable")
    times, values = times[order], values[order]
    keep = np.concatenate(([True], np.diff(times) > 0))
    if not keep.all():
        log.info("%s %s: dropped %d messages with a repeated time stamp", source, topic, int((~keep).sum()))
    return times[keep], values[keep]


def _joint_recording(path: Path, topic_map: TopicMap, present: Mapping[str, str], messages: Mapping[str, list]) -> Recording:
    source = str(path)
    series: dict[str, tuple[np.ndarray, np.ndarray]] = {}
    if topic_map.joint_states:
        topic = topic_map.joint_states
        if present[topic] != _JOINT_STATE:
            raise InputError(source, "topic", topic, f"type {present[topic]}, expected {_JOINT_STATE}")
        for field in JOINT_STATE_FIELDS:
            if all(len(getattr(m, field)) for _, m in messages[topic]):
                series[field] = _joint_series(source, topic, messages[topic], topic_map.joint, field)
    for column, topic, field in (("temperature_c", topic_map.temperature, topic_map.temperature_field),
                                 ("current_a", topic_map.current, topic_map.current_field)):
        if topic:
            series[column] = _scalar_series(source, topic, present[topic], messages[topic], topic_map.joint, field)
    series = {c: _unique_increasing(source, c, *tv) for c, tv in series.items()}
    base_times = next(iter(series.values()))[0]
    lo = max(t[0] for t, _ in series.values())
    hi = min(t[-1] for t, _ in series.values())
    time_s = base_times[(base_times >= lo) & (base_times <= hi)]
    if time_s.size == 0:
        raise InputError(source, "topics", ", ".join(topic_map.topics()), "the topics' time spans do not overlap")
    columns = {c: np.interp(time_s, t, v) for c, (t, v) in series.items()}
    return Recording(name=f"{path.name}:{topic_map.joint}", source=source, joint=topic_map.joint,
                     time_s=time_s - time_s[0], **columns)


def read_bag_joints(path: str | Path, topic_maps: Sequence[TopicMap]) -> dict[str, Recording]:
    """Read several joints from one ROS 1 (``.bag``) or ROS 2 (directory) bag in one pass."""
    path = Path(path)
    present, messages = _read_topics(path, {t for m in topic_maps for t in m.topics()})
    return {m.joint: _joint_recording(path, m, present, messages) for m in topic_maps}


def read_bag(path: str | Path, topic_map: TopicMap) -> Recording:
    """Read one joint's :class:`Recording` from a ROS 1 or ROS 2 bag through ``topic_map``."""
    return read_bag_joints(path, [topic_map])[topic_map.joint]


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
