"""ROS 1 and ROS 2 bags -> :class:`~thermo_ddp.recordings.Recording`: one joint through a :class:`TopicMap`,
several joints of one bag in a single pass with :func:`read_bag_joints`.
"""
from __future__ import annotations

import dataclasses
import logging
from pathlib import Path
from typing import Iterable, Mapping, Sequence

import numpy as np

from .errors import InputError
from .recordings import Recording

log = logging.getLogger(__name__)
JOINT_STATE_FIELDS = ("position", "velocity", "effort")
_JOINT_STATE = "sensor_msgs/msg/JointState"
_SCALAR_TYPES = {"sensor_msgs/msg/Temperature": "temperature", "std_msgs/msg/Float64": "data",
                 "std_msgs/msg/Float32": "data"}

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

