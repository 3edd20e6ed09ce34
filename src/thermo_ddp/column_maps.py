"""Column maps (``--columns MAP.toml``): how any CSV's own columns become the recording contract, and the
CSV reader behind every recording file (pandas' C parser; rows counted as in the file, header row 1).
"""
from __future__ import annotations

import csv
import dataclasses
import math
import tomllib
import warnings
from pathlib import Path
from typing import Mapping, Sequence

import numpy as np
import pandas as pd

from .errors import InputError
from .model.network_spec import check_node_name
from .recordings import COLUMNS, SIGNALS, Recording, RecordingSet, _check_signal, _check_time, sensor_column, sensor_node

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


_MAP_KEYS = {"time": ("column", "step_s"), "columns": SIGNALS, "rows": ("skip_incomplete", "split_gaps_s"),
             "sensors": None}  # [sensors]: node name = source column (any valid node name)
_SOURCE_KEYS = ("column", "norm", "scale", "offset")
GAP_FACTOR = 10.0  # default split: a gap longer than 10 median sample steps


@dataclasses.dataclass(frozen=True)
class ColumnMap:
    """How a CSV's own columns become the recording contract (docs/architecture.md, "Column map").

    Time: ``time_column`` (seconds, or ISO 8601 date-times, quoted or not; date-times count from the
    first sample) or a fixed ``step_s``.  ``skip_incomplete``: drop rows with an empty cell in a mapped
    column (counted) instead of refusing the file.  ``split_gaps_s``: a longer gap between samples
    splits the file into segments (None: ``GAP_FACTOR`` x the median step; inf: never).  ``columns``
    maps contract columns, the ``[sensors]`` table's nodes included as ``node_<name>_c``."""

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

    def key(self, contract: str) -> str:
        """The map's key of a contract column: ``columns.current_a`` or ``sensors.tooth``."""
        node = sensor_node(contract)
        return f"sensors.{node}" if node else f"columns.{contract}"

    def wanted_by(self, column: str) -> str:
        """The map keys that read the CSV ``column`` (for messages)."""
        if column == self.time_column:
            return "time.column"
        return ", ".join(self.key(c) for c, s in self.columns.items() if column in s.columns)

    def check_writable(self, available: Sequence[str]) -> None:
        """Refuse, before any work, a map that a logger of the contract columns ``available`` cannot write
        a CSV for (:meth:`write_csv`): a fixed step instead of a time column, a norm (not invertible), a
        zero scale, a contract column the logger lacks, or two columns written under one name."""
        if self.time_column is None:
            raise _map_error(self.source, "time.step_s", self.step_s, "a logger with time stamps writes a time "
                             "column: give [time] column")
        names = [self.time_column]
        for contract, src in self.columns.items():
            key = self.key(contract)
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
        if _MAP_KEYS[section] is not None and key not in _MAP_KEYS[section]:
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
    time, cols, rows, sensors = (_map_section(source, data, s) for s in _MAP_KEYS)
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
    mapped = {k: _map_source(source, f"columns.{k}", v) for k, v in cols.items()}
    mapped |= {sensor_column(check_node_name(source, "sensors", k)): _map_source(source, f"sensors.{k}", v)
               for k, v in sensors.items()}
    return ColumnMap(source, mapped, column, step, skip, split)


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
            raise InputError(source, column, "missing", f"no such column (wanted by {columns.source} "
                             f"{columns.wanted_by(column)}); the CSV has: {', '.join(header)}", row=1)
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
    sensors = {sensor_node(c): signals.pop(c) for c in list(signals) if sensor_node(c)}
    recordings = tuple(Recording(name=name if len(segments) == 1 else f"{name}#{k + 1}", source=source,
                                 row_offset=int(rows[a]), time_s=time_s[a:b], **{c: v[a:b] for c, v in signals.items()},
                                 sensors={n: v[a:b] for n, v in sensors.items()})
                       for k, (a, b) in enumerate(segments))
    return RecordingSet(recordings, int(keep.sum()), int(incomplete.sum()))


def read_csv(path: str | Path, name: str | None = None) -> Recording:
    """Read a contract CSV (columns named as in the contract) into one :class:`Recording`."""
    path = Path(path)
    source = str(path)
    header = _header(source, path)
    for column in header:
        if column not in COLUMNS and not sensor_node(column):
            raise InputError(source, column or "(empty header cell)", "column",
                             f"unknown column; the contract columns are {', '.join(COLUMNS)} and node_<name>_c "
                             "(other names: give a column map)", row=1)
    if "time_s" not in header:
        raise InputError(source, "time_s", "missing", "every recording needs a time_s column", row=1)
    return read_mapped_csv(path, ColumnMap.contract(header, source), name).recordings[0]
