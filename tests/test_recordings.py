"""Recordings: contract CSV validation, ROS 1 bag (real, written by ROS) and ROS 2 bag round trip."""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from thermo_ddp.errors import InputError
from thermo_ddp.recordings import (COLUMNS, Recording, TopicMap, column_map_from_dict, common_time, load_column_map,
                                   read_bag, read_bag_joints, read_csv, read_mapped_csv, resample)

PANDA_TOPIC = "/joint_states_fake"


def _write(path: Path, header: list[str], rows: list[list[str]]) -> Path:
    path.write_text("\n".join(",".join(r) for r in [header] + rows) + "\n")
    return path


def _valid_table(n: int, columns: list[str]) -> dict[str, np.ndarray]:
    rng = np.random.default_rng(n)
    data = {"time_s": np.cumsum(rng.uniform(0.001, 1.0, n))}
    for c in columns:
        data[c] = rng.uniform(15.0, 90.0, n) if c.endswith("_c") else rng.normal(0, 5, n)
    return data


# ---------- CSV ----------

signal_columns = st.lists(st.sampled_from(COLUMNS[1:]), min_size=1, max_size=4, unique=True)
fuzz = settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])


@fuzz
@given(n=st.integers(2, 30), columns=signal_columns)
def test_valid_csv_round_trips(tmp_path, n, columns):
    data = _valid_table(n, columns)
    rec = Recording(name="r", **data)
    back = read_csv(rec.to_csv(tmp_path / "r.csv"))
    assert back.columns == rec.columns
    for c in rec.columns:
        np.testing.assert_array_equal(getattr(back, c), getattr(rec, c))


@fuzz
@given(n=st.integers(2, 30), columns=signal_columns, data=st.data())
def test_nan_names_column_and_row(tmp_path, n, columns, data):
    table = _valid_table(n, columns)
    column = data.draw(st.sampled_from(["time_s"] + columns))
    row = data.draw(st.integers(0, n - 1))
    table[column][row] = np.nan
    path = _write(tmp_path / "nan.csv", list(table), [[repr(float(table[c][i])) for c in table] for i in range(n)])
    with pytest.raises(InputError) as err:
        read_csv(path)
    assert (err.value.field, err.value.row) == (column, row + 2)
    assert "nan.csv" in str(err.value) and f"row {row + 2}" in str(err.value)


@fuzz
@given(n=st.integers(3, 30), data=st.data())
def test_non_increasing_time_names_row(tmp_path, n, data):
    table = _valid_table(n, ["effort"])
    row = data.draw(st.integers(1, n - 1))
    table["time_s"][row] = table["time_s"][row - 1] - data.draw(st.sampled_from([0.0, 0.5, 10.0]))
    path = _write(tmp_path / "t.csv", list(table), [[repr(float(table[c][i])) for c in table] for i in range(n)])
    with pytest.raises(InputError) as err:
        read_csv(path)
    assert (err.value.field, err.value.row) == ("time_s", row + 2)


@fuzz
@given(n=st.integers(2, 30), column=st.sampled_from(["temperature_c", "ambient_c"]),
       kelvin=st.floats(250.0, 420.0), data=st.data())
def test_kelvin_temperatures_rejected(tmp_path, n, column, kelvin, data):
    table = _valid_table(n, [column])
    row = data.draw(st.integers(0, n - 1))
    table[column][row] = kelvin
    path = _write(tmp_path / "k.csv", list(table), [[repr(float(table[c][i])) for c in table] for i in range(n)])
    with pytest.raises(InputError, match="kelvin") as err:
        read_csv(path)
    assert (err.value.field, err.value.row) == (column, row + 2)


@fuzz
@given(cell=st.sampled_from(["abc", "", "1,2", "12 V", "--"]), row=st.integers(0, 4))
def test_non_numeric_cell(tmp_path, cell, row):
    rows = [[str(i * 0.1), "1.0"] for i in range(5)]
    rows[row][1] = cell
    path = _write(tmp_path / "x.csv", ["time_s", "effort"], rows)
    with pytest.raises(InputError) as err:
        read_csv(path)
    assert err.value.row == row + 2


@pytest.mark.parametrize("text, field", [("", "file"), ("time_s,effort\n", "file"), ("effort\n1\n2\n", "time_s"),
                                         ("time_s,torque\n0,1\n", "torque"), ("time_s,effort\n0,1,2\n", "row")])
def test_bad_files(tmp_path, text, field):
    path = tmp_path / "bad.csv"
    path.write_text(text)
    with pytest.raises(InputError) as err:
        read_csv(path)
    assert err.value.field == field and "bad.csv" in str(err.value)


def test_missing_column_required_by_analysis(tmp_path):
    rec = Recording(name="r", time_s=[0.0, 1.0], effort=[1.0, 2.0])
    with pytest.raises(InputError, match="temperature_c"):
        rec.require("effort", "temperature_c")


def test_resample_linear_and_bounded():
    rec = Recording(name="r", time_s=[0.0, 1.0, 3.0], position=[0.0, 2.0, 6.0])
    out = resample(rec, [0.5, 2.0])
    np.testing.assert_allclose(out.position, [1.0, 4.0])
    with pytest.raises(InputError, match="outside"):
        resample(rec, [0.0, 4.0])
    other = Recording(name="s", time_s=np.linspace(0.5, 5.0, 10), effort=np.ones(10))
    grid = common_time([rec, other])
    assert grid[0] == 0.5 and grid[-1] <= 3.0 and np.all(np.diff(grid) > 0)


# ---------- ROS 1: a real bag written by ROS ----------

def test_real_ros1_bag_panda_joint4(panda_bag):
    rec = read_bag(panda_bag, TopicMap("panda_joint4", joint_states=PANDA_TOPIC))
    assert len(rec) == 4211 and rec.joint == "panda_joint4"
    assert 139.0 < rec.time_s[-1] < 141.0
    assert rec.columns == ("time_s", "position", "velocity", "effort")
    # panda_joint4 range is [-3.0718, -0.0698] rad (Franka Panda datasheet joint limits)
    assert np.all((rec.position > -3.0718) & (rec.position < -0.0698))
    # oracle: the low-level ROS 1 reader, decoding raw messages and indexing by name independently
    from rosbags.rosbag1 import Reader
    from rosbags.typesys import Stores, get_typestore

    store = get_typestore(Stores.ROS1_NOETIC)
    with Reader(panda_bag) as reader:
        raw = [store.deserialize_ros1(d, c.msgtype) for c, _, d in reader.messages()]
    stamps = np.array([m.header.stamp.sec + 1e-9 * m.header.stamp.nanosec for m in raw])
    np.testing.assert_allclose(rec.time_s, stamps - stamps[0], atol=1e-9)
    for field in ("position", "velocity", "effort"):
        np.testing.assert_array_equal(getattr(rec, field), [getattr(m, field)[3] for m in raw])


def test_real_bag_several_joints_one_pass(panda_bag):
    joints = read_bag_joints(panda_bag, [TopicMap(f"panda_joint{i}", joint_states=PANDA_TOPIC) for i in (1, 4, 7)])
    assert set(joints) == {"panda_joint1", "panda_joint4", "panda_joint7"}
    assert not np.allclose(joints["panda_joint1"].position, joints["panda_joint4"].position)


def test_missing_topic_lists_bag_topics(panda_bag):
    with pytest.raises(InputError) as err:
        read_bag(panda_bag, TopicMap("panda_joint4", joint_states=PANDA_TOPIC, temperature="/motor_temperature"))
    message = str(err.value)
    assert "/motor_temperature" in message and PANDA_TOPIC in message and "\n" not in message


def test_unknown_joint_named(panda_bag):
    with pytest.raises(InputError, match="panda_joint9.*panda_joint1"):
        read_bag(panda_bag, TopicMap("panda_joint9", joint_states=PANDA_TOPIC))


@pytest.mark.parametrize("fraction", [0.001, 0.5, 0.999])
def test_truncated_bag(tmp_path, fraction, panda_bag):
    data = panda_bag.read_bytes()
    cut = tmp_path / "cut.bag"
    cut.write_bytes(data[: int(len(data) * fraction)])
    with pytest.raises(InputError, match="cut.bag"):
        read_bag(cut, TopicMap("panda_joint4", joint_states=PANDA_TOPIC))


# ---------- ROS 2: written here with rosbags, read back ----------

def _write_ros2_bag(path: Path, n: int = 200) -> dict[str, np.ndarray]:
    from rosbags.rosbag2 import Writer
    from rosbags.typesys import Stores, get_typestore

    store = get_typestore(Stores.ROS2_HUMBLE)
    Time, Header = store.types["builtin_interfaces/msg/Time"], store.types["std_msgs/msg/Header"]
    JointState = store.types["sensor_msgs/msg/JointState"]
    Temperature, Float64 = store.types["sensor_msgs/msg/Temperature"], store.types["std_msgs/msg/Float64"]
    t = 100.0 + 0.01 * np.arange(n)
    truth = {"time_s": t - t[0], "position": np.sin(t), "velocity": np.cos(t), "effort": 3 * np.sin(2 * t),
             "temperature_c": 40 + 0.1 * np.arange(n), "current_a": 2 + np.sin(3 * t)}
    with Writer(path, version=8) as writer:
        js = writer.add_connection("/joint_states", JointState.__msgtype__, typestore=store)
        temp = writer.add_connection("/arm_left_4/temperature", Temperature.__msgtype__, typestore=store)
        cur = writer.add_connection("/arm_left_4/current", Float64.__msgtype__, typestore=store)
        for k, tk in enumerate(t):
            ns = int(round(tk * 1e9))
            header = Header(stamp=Time(sec=int(ns // 10**9), nanosec=int(ns % 10**9)), frame_id="")
            msg = JointState(header=header, name=["arm_left_3_joint", "arm_left_4_joint"],
                             position=np.array([0.0, truth["position"][k]]),
                             velocity=np.array([0.0, truth["velocity"][k]]), effort=np.array([0.0, truth["effort"][k]]))
            writer.write(js, ns, store.serialize_cdr(msg, msg.__msgtype__))
            tm = Temperature(header=header, temperature=float(truth["temperature_c"][k]), variance=0.0)
            writer.write(temp, ns, store.serialize_cdr(tm, tm.__msgtype__))
            writer.write(cur, ns, store.serialize_cdr(Float64(data=float(truth["current_a"][k])), Float64.__msgtype__))
    return truth


def test_ros2_bag_round_trip(tmp_path):
    truth = _write_ros2_bag(tmp_path / "bag2")
    rec = read_bag(tmp_path / "bag2", TopicMap("arm_left_4_joint", joint_states="/joint_states",
                                               temperature="/arm_left_4/temperature", current="/arm_left_4/current"))
    for column, values in truth.items():
        np.testing.assert_allclose(getattr(rec, column), values, atol=1e-6, err_msg=column)


def test_ros2_current_from_joint_state_effort(tmp_path):
    truth = _write_ros2_bag(tmp_path / "bag2", n=20)
    rec = read_bag(tmp_path / "bag2", TopicMap("arm_left_4_joint", joint_states=None, current="/joint_states"))
    np.testing.assert_allclose(rec.current_a, truth["effort"], atol=1e-12)


# ---------- column maps: any CSV's own columns ----------

def _messy_csv(path: Path, data) -> dict:
    """A log as real ones are: own column names, ISO 8601 stamps (some quoted, some quoted twice), empty
    cells, a gap; returns what a correct reader must produce."""
    n = data.draw(st.integers(4, 40), label="rows")
    step = data.draw(st.sampled_from([0.25, 1.0, 2.5]), label="step_s")
    gap_after = data.draw(st.integers(1, n - 2), label="gap after row")
    t = step * np.arange(n) + np.where(np.arange(n) > gap_after, 1000.0, 0.0)
    rng = np.random.default_rng(data.draw(st.integers(0, 2 ** 16), label="seed"))
    temp, i_d, i_q = rng.uniform(20, 90, n), rng.normal(0, 50, n), rng.normal(0, 50, n)
    rpm = rng.uniform(-3000, 3000, n)
    empty = set(data.draw(st.lists(st.integers(0, n - 1), max_size=n // 3, unique=True), label="empty rows"))
    start = np.datetime64("2022-10-26T08:17:21.847")
    lines = ["Num,Stamp,T_wind ,i_d,i_q,speed_rpm,notes"]
    for k in range(n):
        stamp = str(start + np.timedelta64(int(round(t[k] * 1000)), "ms")) + "Z"
        stamp = data.draw(st.sampled_from([stamp, f'"{stamp}"', f'"""{stamp}"""']), label="quoting")
        cells = [str(k), stamp, *(repr(float(x[k])) for x in (temp, i_d, i_q, rpm)), "x"]
        if k in empty:
            cells[data.draw(st.integers(2, 5), label="empty column")] = ""
        lines.append(",".join(cells))
    path.write_text("\n".join(lines) + "\n")
    keep = np.array([k not in empty for k in range(n)])
    return {"t": t[keep] - t[keep][0], "temperature_c": temp[keep], "current_a": np.hypot(i_d, i_q)[keep],
            "velocity": (rpm * np.pi / 30)[keep], "skipped": len(empty), "gap_s": 1000.0 * 0.5}


MESSY_MAP = {"time": {"column": "Stamp"},
             "columns": {"temperature_c": "T_wind", "current_a": {"norm": ["i_d", "i_q"]},
                         "velocity": {"column": "speed_rpm", "scale": math.pi / 30}},
             "rows": {"skip_incomplete": True, "split_gaps_s": 500.0}}


@fuzz
@given(data=st.data())
def test_column_map_reads_messy_logs(tmp_path, data):
    truth = _messy_csv(tmp_path / "log.csv", data)
    if truth["t"].size == 0:
        return
    read = read_mapped_csv(tmp_path / "log.csv", column_map_from_dict(MESSY_MAP, "map.toml"))
    assert read.rows["skipped"] == truth["skipped"] and read.rows["used"] == truth["t"].size
    jumps = np.flatnonzero(np.diff(truth["t"]) > 500.0)
    assert read.rows["segments"] == jumps.size + 1
    for column in ("temperature_c", "current_a", "velocity"):
        np.testing.assert_allclose(np.concatenate([getattr(r, column) for r in read.recordings]), truth[column],
                                   rtol=1e-12, err_msg=column)
    time_s = np.concatenate([r.time_s for r in read.recordings])
    np.testing.assert_allclose(time_s, truth["t"], atol=1e-6)  # ms stamps


def _map_file(tmp_path: Path, text: str) -> Path:
    path = tmp_path / "map.toml"
    path.write_text(text)
    return path


@pytest.mark.parametrize("text, field", [
    ('[time]\ncolumn = "t"\n[columns]\ntemperature_c = "T"\n[rows]\nskip_empty = true\n', "rows.skip_empty"),
    ('[time]\ncolumn = "t"\n[columns]\ntorque = "T"\n', "columns.torque"),
    ('[time]\ncolumn = "t"\nstep_s = 1.0\n[columns]\ncurrent_a = "i"\n', "[time]"),
    ('[time]\nstep_s = -1\n[columns]\ncurrent_a = "i"\n', "time.step_s"),
    ('[time]\ncolumn = "t"\n[columns]\ncurrent_a = { norm = "i" }\n', "columns.current_a.norm"),
    ('[time]\ncolumn = "t"\n[columns]\ncurrent_a = { column = "i", gain = 2 }\n', "columns.current_a.gain"),
    ('[time]\ncolumn = "t"\n[colums]\ncurrent_a = "i"\n', "[colums]"),
    ('[time]\ncolumn = "t"\n[columns]\n', "[columns]"),
])
def test_bad_column_map_names_map_and_key(tmp_path, text, field):
    with pytest.raises(InputError) as err:
        load_column_map(_map_file(tmp_path, text))
    assert err.value.field == field and "map.toml" in str(err.value) and "\n" not in str(err.value)


def test_column_map_missing_column_empty_cell_and_bad_stamp(tmp_path):
    cmap = load_column_map(_map_file(tmp_path, '[time]\ncolumn = "Stamp"\n[columns]\ncurrent_a = "I"\n'))
    csv_path = tmp_path / "log.csv"
    csv_path.write_text("Stamp,J\n2022-10-26T08:00:00Z,1\n")
    with pytest.raises(InputError) as err:
        read_mapped_csv(csv_path, cmap)
    assert (err.value.field, err.value.row) == ("I", 1) and "log.csv" in str(err.value)
    csv_path.write_text("Stamp,I\n2022-10-26T08:00:00Z,1\n2022-10-26T08:00:01Z,\n")
    with pytest.raises(InputError, match="skip_incomplete") as err:
        read_mapped_csv(csv_path, cmap)
    assert (err.value.field, err.value.row) == ("I", 3)
    csv_path.write_text("Stamp,I\n2022-10-26T08:00:00Z,1\n26/10/2022 08:00:01,2\n")
    with pytest.raises(InputError, match="ISO 8601") as err:
        read_mapped_csv(csv_path, cmap)
    assert (err.value.field, err.value.row) == ("Stamp", 3)


def test_step_time_scale_offset_and_default_gap_split(tmp_path):
    """step_s: the time of a row is its position in the file; dropped rows keep the time base; a gap of
    more than 10 median steps splits."""
    cmap = column_map_from_dict({"time": {"step_s": 0.5}, "columns": {"temperature_c": {"column": "K", "offset": -273.15}},
                                 "rows": {"skip_incomplete": True}}, "m")
    csv_path = tmp_path / "s.csv"
    csv_path.write_text("K,note\n300,a\n301,b\n,c\n302,d\n")
    read = read_mapped_csv(csv_path, cmap)
    rec, = read.recordings
    np.testing.assert_allclose(rec.time_s, [0.0, 0.5, 1.5])  # the empty row (file row 4) is skipped, counted
    np.testing.assert_allclose(rec.temperature_c, [26.85, 27.85, 28.85])
    assert read.rows == {"used": 3, "skipped": 1, "segments": 1}
    stamps = np.r_[np.arange(20.0), 40.0 + np.arange(5.0)]
    csv_path.write_text("t,I\n" + "".join(f"{t},{t}\n" for t in stamps))
    read = read_mapped_csv(csv_path, column_map_from_dict({"time": {"column": "t"}, "columns": {"current_a": "I"}}))
    assert [len(r) for r in read.recordings] == [20, 5] and read.recordings[1].time_s[0] == 40.0


@pytest.mark.parametrize("column, value", [("current_a", "2e4"), ("velocity", "-3e4"), ("voltage_v", "1e5")])
def test_implausible_magnitudes_named(tmp_path, column, value):
    path = _write(tmp_path / "m.csv", ["time_s", column], [["0", "1"], ["1", value]])
    with pytest.raises(InputError, match="implausible") as err:
        read_csv(path)
    assert (err.value.field, err.value.row) == (column, 3)


# --- several sensors: node_<name>_c columns and a column map's [sensors] table ----------------------
def _multi_sensor() -> Recording:
    t = np.arange(0.0, 10.0)
    return Recording("m", t, current_a=np.ones_like(t), temperature_c=30 + t, sensors={"tooth": 25 + t, "yoke": 20 + t / 2})


def test_node_columns_round_trip_through_the_contract_csv(tmp_path):
    rec = _multi_sensor()
    back = read_csv(rec.to_csv(tmp_path / "m.csv"))
    assert back.sensor_columns == ("node_tooth_c", "node_yoke_c")
    for node, values in rec.sensors.items():
        np.testing.assert_array_equal(back.sensors[node], values)
    by_node = back.temperatures_by_node("winding")
    assert set(by_node) == {"winding", "tooth", "yoke"}
    np.testing.assert_array_equal(by_node["winding"], rec.temperature_c)


def test_take_and_resample_carry_the_sensors():
    rec = _multi_sensor()
    part = rec.take(slice(3, 7))
    np.testing.assert_array_equal(part.sensors["yoke"], rec.sensors["yoke"][3:7])
    assert part.row_offset == 3 and len(part) == 4
    half = resample(rec, np.arange(0.0, 9.0, 0.5))
    np.testing.assert_allclose(half.sensors["tooth"], 25 + np.arange(0.0, 9.0, 0.5))
    with pytest.raises(ValueError):
        rec.sensors["tooth"][0] = 0.0  # read-only like every column


def test_a_map_reads_its_sensors_table(tmp_path):
    csv = _write(tmp_path / "log.csv", ["t", "I", "Tw", "Tt"], [["0", "1", "30", "25"], ["1", "1", "31", "26"]])
    cmap = column_map_from_dict({"time": {"column": "t"}, "columns": {"current_a": "I", "temperature_c": "Tw"},
                                 "sensors": {"tooth": {"column": "Tt", "offset": 0.5}}}, "map.toml")
    rec, = read_mapped_csv(csv, cmap).recordings
    np.testing.assert_array_equal(rec.sensors["tooth"], [25.5, 26.5])
    assert cmap.wanted_by("Tt") == "sensors.tooth"


@pytest.mark.parametrize("sensors, field", [({"2nd": np.zeros(10)}, "sensors"), ({"tooth": np.zeros(9)}, "node_tooth_c"),
                                            ({"tooth": np.full(10, 350.0)}, "node_tooth_c")])
def test_bad_sensors_are_refused(sensors, field):
    with pytest.raises(InputError) as err:
        Recording("bad", np.arange(10.0), temperature_c=np.zeros(10), sensors=sensors)
    assert f"{field} = " in str(err.value)
