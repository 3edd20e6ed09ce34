"""Recordings: one joint's measured signals on one time base, read from CSV or ROS 1/ROS 2 bags.

The CSV contract (docs/architecture.md): a header row, one sample per row, ``time_s`` (strictly
increasing seconds) and any of ``current_a``, ``temperature_c`` (the casing sensor), ``position``,
``velocity``, ``effort`` (ROS ``JointState`` meaning, SI units of the joint), ``ambient_c``,
``voltage_v``.  Every problem with the input raises one :class:`~thermo_ddp.errors.InputError`
naming the file, the column (or topic) and the row.  Rows are counted as in the file: the
header is row 1, the first sample row 2.  For bags and in-memory arrays the row is the sample
index (0-based) on the recording's time base.

A bag is read through a :class:`TopicMap` (one joint).  Several joints of one bag are read in
a single pass with :func:`read_bag_joints`.
"""
from __future__ import annotations

import csv
import dataclasses
import logging
from pathlib import Path
from typing import Iterable, Mapping, Sequence

import numpy as np

from .errors import InputError

log = logging.getLogger(__name__)

SIGNALS = ("current_a", "temperature_c", "position", "velocity", "effort", "ambient_c", "voltage_v")
COLUMNS = ("time_s",) + SIGNALS
_CELSIUS_COLUMNS = ("temperature_c", "ambient_c")
KELVIN_SUSPECT_C = 200.0  # a motor casing or a room above 200 degC means the file holds kelvin
JOINT_STATE_FIELDS = ("position", "velocity", "effort")
_JOINT_STATE = "sensor_msgs/msg/JointState"
_SCALAR_TYPES = {"sensor_msgs/msg/Temperature": "temperature", "std_msgs/msg/Float64": "data",
                 "std_msgs/msg/Float32": "data"}


def _check_signal(source: str, column: str, values: np.ndarray, row_of) -> None:
    """Raise InputError on the first NaN/inf or kelvin-looking temperature in ``values``."""
    bad = np.flatnonzero(~np.isfinite(values))
    if bad.size:
        raise InputError(source, column, values[bad[0]], "not a finite number", row=row_of(bad[0]))
    if column in _CELSIUS_COLUMNS:
        hot = np.flatnonzero((values > KELVIN_SUSPECT_C) | (values < -273.15))
        if hot.size:
            raise InputError(source, column, float(values[hot[0]]),
                             f"outside -273.15..{KELVIN_SUSPECT_C:g} degC: looks like kelvin or a wrong unit; "
                             "give degrees Celsius", row=row_of(hot[0]))


def _check_time(source: str, time_s: np.ndarray, row_of) -> None:
    _check_signal(source, "time_s", time_s, row_of)
    step = np.diff(time_s)
    bad = np.flatnonzero(step <= 0)
    if bad.size:
        k = bad[0] + 1
        raise InputError(source, "time_s", float(time_s[k]),
                         f"not strictly increasing (previous sample {time_s[k - 1]!r})", row=row_of(k))


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


def _parse_cell(source: str, column: str, cell: str, row: int) -> float:
    try:
        return float(cell)
    except ValueError:
        raise InputError(source, column, cell, "not a number", row=row) from None


def read_csv(path: str | Path, name: str | None = None) -> Recording:
    """Read a contract CSV into a :class:`Recording` (InputError on any bad cell, row or column)."""
    path = Path(path)
    source = str(path)
    try:
        with path.open(newline="") as handle:
            lines = list(csv.reader(handle))
    except (OSError, UnicodeDecodeError) as err:
        raise InputError(source, "file", "unreadable", str(err)) from None
    lines = [line for line in lines if any(cell.strip() for cell in line)]
    if not lines:
        raise InputError(source, "file", "empty", "no header row and no samples")
    header = [cell.strip() for cell in lines[0]]
    for column in header:
        if column not in COLUMNS:
            raise InputError(source, column or "(empty header cell)", "column",
                             f"unknown column; the contract columns are {', '.join(COLUMNS)}", row=1)
    if len(set(header)) != len(header):
        raise InputError(source, "header", ",".join(header), "a column appears twice", row=1)
    if "time_s" not in header:
        raise InputError(source, "time_s", "missing", "every recording needs a time_s column", row=1)
    rows = lines[1:]
    if not rows:
        raise InputError(source, "file", "header only", "no samples after the header", row=2)
    data = np.empty((len(rows), len(header)))
    for i, cells in enumerate(rows):
        if len(cells) != len(header):
            raise InputError(source, "row", ",".join(cells), f"{len(cells)} cells, header has {len(header)}", row=i + 2)
        for j, cell in enumerate(cells):
            data[i, j] = _parse_cell(source, header[j], cell.strip(), i + 2)
    columns = {c: data[:, j] for j, c in enumerate(header)}
    return Recording(name=name or path.name, source=source, row_offset=2, **columns)


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
