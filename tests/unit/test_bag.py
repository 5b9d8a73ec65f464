"""fourws_bringup.bag (its modules schema, metadata, writer, reader, run_data, recovery):
schema text, rosbag2 layout, reading back independently, recovery.

Oracles: ``rosbags`` (an independent reader of rosbag2 folders and MCAP, with its own msg
parser and RIHS01 hashing), the installed ``.json`` type descriptions (type hashes), mcap's
own index (chunk boundaries), and the values that were serialized with rclpy.
"""

from __future__ import annotations

import json
import math
import shutil
from pathlib import Path

import numpy as np
import pytest
import yaml
from hypothesis import given, settings
from hypothesis import strategies as st

pytest.importorskip("rclpy")
from builtin_interfaces.msg import Time  # noqa: E402
from nav_msgs.msg import Odometry  # noqa: E402
from rclpy.serialization import serialize_message  # noqa: E402
from rosgraph_msgs.msg import Clock  # noqa: E402
from std_msgs.msg import String  # noqa: E402

from fourws_bringup.bag.errors import BagError  # noqa: E402
from fourws_bringup.bag.recovery import recover  # noqa: E402
from fourws_bringup.bag.run_data import read_run  # noqa: E402
from fourws_bringup.bag.schema import (  # noqa: E402
    cdr_stamp_ns,
    message_definition,
    msg_dependencies,
    msg_file,
    type_hash,
)
from fourws_bringup.bag.writer import BagWriter  # noqa: E402
from fourws_bringup.scoring import step_latencies_ms  # noqa: E402
from fourws_common.topics import DEFAULT_TOPICS, TOPICS, topic_info  # noqa: E402
from fourws_msgs.msg import (  # noqa: E402
    MpcCommand,
    MpcDiagnostics,
    ReferenceTrajectory,
    VehicleState,
    WheelTorques,
)

DT_NS = 10_000_000


def stamp(k: int) -> Time:
    ns = k * DT_NS
    return Time(sec=ns // 1_000_000_000, nanosec=ns % 1_000_000_000)


def vehicle_state(k: int, x: float | None = None) -> VehicleState:
    m = VehicleState()
    m.header.stamp = stamp(k)
    m.header.frame_id = "map"
    m.x = float(k) if x is None else x
    m.y = 0.01 * k
    m.yaw = 0.001 * k
    m.vx = 16.7
    m.vy = -0.002 * k
    m.yaw_rate = 0.003 * k
    m.sideslip = math.atan2(m.vy, m.vx)
    m.steer_front = 0.0001 * k
    m.wheel_speed = [1.0 * k, 2.0 * k, 3.0 * k, 4.0 * k]
    m.fz = [1800.0 + k, 1810.0, 1820.0, 1830.0 - k]
    m.mu = [0.5, 0.5, 0.5, 0.5]
    return m


def mpc_command(k: int) -> MpcCommand:
    return MpcCommand(header=vehicle_state(k).header, delta_front=0.01 * k,
                      delta_rear=-0.005 * k, yaw_moment=10.0 * k)


def diagnostics(k: int) -> MpcDiagnostics:
    return MpcDiagnostics(header=vehicle_state(k).header, controller="improved",
                          np=12 + k % 9, nc=6 + k % 5, q_y=4000.0 + k, q_phi=2500.0,
                          r_ddelta=40000.0, r_dmz=30000.0, lateral_error=0.001 * k,
                          heading_error=-0.0005 * k, solve_time_ms=1.0 + 0.01 * k,
                          solver_status="solved", iterations=k, fallback=k % 7 == 0)


def wheel_torques(k: int) -> WheelTorques:
    return WheelTorques(header=vehicle_state(k).header, torque=[10.0 + k, 11.0, 12.0, 13.0 - k],
                        allocation="optimal")


def reference() -> ReferenceTrajectory:
    m = ReferenceTrajectory()
    m.header.frame_id = "map"
    x = np.linspace(0.0, 100.0, 201)
    m.x, m.y = x.tolist(), (0.1 * np.sin(x / 10)).tolist()
    m.yaw = np.arctan(0.01 * np.cos(x / 10)).tolist()
    m.curvature, m.speed = [0.0] * 201, [16.7] * 201
    return m


def write_run_bag(folder: Path, steps: int = 120, chunk_size: int = 4096,
                  republish: bool = False) -> dict[str, list]:
    """A bag as the recorder writes it; returns {topic: [(log_time, msg), ...]} written."""
    topics = [topic_info(t) for t in DEFAULT_TOPICS]
    w = BagWriter(folder, topics, chunk_size_bytes=chunk_size)
    written: dict[str, list] = {t: [] for t in DEFAULT_TOPICS}
    t_ns = 1_700_000_000_000_000_000

    def put(topic: str, msg) -> None:
        nonlocal t_ns
        t_ns += 1000
        w.write(topic, serialize_message(msg), t_ns)
        written[topic].append((t_ns, msg))

    put("/reference/trajectory", reference())
    put("/run/status", String(data=json.dumps({"state": "running", "scenario": "dlc"})))
    for k in range(steps):
        put("/clock", Clock(clock=stamp(k)))
        put("/vehicle/state", vehicle_state(k))
        if republish and k % 10 == 3:
            put("/vehicle/state", vehicle_state(k, x=-1.0))  # a repeat: read_run keeps the first
        odom = Odometry()
        odom.header = vehicle_state(k).header
        odom.pose.pose.position.x = float(k)
        put("/vehicle/odom", odom)
        put("/control/mpc_command", mpc_command(k))
        put("/control/mpc_diagnostics", diagnostics(k))
        put("/control/wheel_torques", wheel_torques(k))
    put("/run/status", String(data=json.dumps({"state": "ended", "completed": True,
                                               "scenario": "dlc", "steps": steps})))
    w.close()
    return written


# -- schema text -------------------------------------------------------------------------------
def test_vehicle_state_schema_parses_with_rosbags_including_its_dependencies():
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore

    text = message_definition("fourws_msgs/msg/VehicleState")
    types = get_types_from_msg(text, "fourws_msgs/msg/VehicleState")
    assert {"fourws_msgs/msg/VehicleState", "std_msgs/msg/Header",
            "builtin_interfaces/msg/Time"} <= set(types)
    fields = [f[0] for f in types["fourws_msgs/msg/VehicleState"][1]]
    assert fields[:3] == ["header", "x", "y"] and "mu" in fields
    assert text.count("=" * 80 + "\nMSG: std_msgs/Header\n") == 1
    assert text.count("=" * 80 + "\nMSG: builtin_interfaces/Time\n") == 1
    store = get_typestore(Stores.EMPTY)
    store.register(types)
    assert store.hash_rihs01("fourws_msgs/msg/VehicleState") == type_hash(
        "fourws_msgs/msg/VehicleState")


def _rosidl_hash(typ: str) -> str:
    """The RIHS01 hash rosidl generated for a type (its installed ``.json``)."""
    data = json.loads(msg_file(typ).with_suffix(".json").read_text(encoding="utf-8"))
    return next(e["hash_string"] for e in data["type_hashes"] if e["type_name"] == typ)


def _store_from_msg_files(typ: str):
    """A rosbags type store holding ``typ`` and everything it uses, each registered from its
    own installed ``.msg`` file (fourws_msgs too), not from the schema text under test."""
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore

    store, todo, seen = get_typestore(Stores.EMPTY), [typ], set()
    while todo:
        t = todo.pop()
        if t in seen:
            continue
        seen.add(t)
        text = msg_file(t).read_text(encoding="utf-8")
        store.register(get_types_from_msg(text, t))
        todo += [f"{d.split('/')[0]}/msg/{d.split('/')[1]}"
                 for d in msg_dependencies(text, t.split("/")[0])]
    return store


@pytest.mark.parametrize("topic", DEFAULT_TOPICS)
def test_every_graph_type_has_a_complete_definition(topic):
    """Complete = RIHS01 of the schema text (rosbags) equals the hash rosidl generated."""
    typ = TOPICS[topic].type
    assert type_hash(typ).startswith("RIHS01_")
    assert type_hash(typ) == _rosidl_hash(typ)


@pytest.mark.parametrize("topic", DEFAULT_TOPICS)
def test_schema_text_against_rosbags_generate_msgdef(topic):
    """rosbags' ``generate_msgdef`` from the installed .msg files describes the same fields
    as the schema text, and ``hash_rihs01`` gives the same hash; but its text is not the
    bytes rosbag2 writes (it drops the comments and layout of the .msg files), which is why
    bag/schema.py keeps its own text (see its docstring)."""
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore

    typ = TOPICS[topic].type
    ours = message_definition(typ)
    files = _store_from_msg_files(typ)
    parsed = get_typestore(Stores.EMPTY)
    parsed.register(get_types_from_msg(ours, typ))
    generated, _ = files.generate_msgdef(typ, ros_version=2)
    assert parsed.generate_msgdef(typ, ros_version=2)[0] == generated
    assert files.hash_rihs01(typ) == type_hash(typ)
    assert ours.startswith(msg_file(typ).read_text(encoding="utf-8").rstrip("\n"))
    assert generated != ours


def test_dependencies_of_a_msg_text():
    text = ("# comment with std_msgs/Nope\nHeader header\nstd_msgs/ColorRGBA c # x\n"
            "Point[] pts\ngeometry_msgs/msg/Vector3[3] v\nuint8 A=1\nstring<=5 s\n"
            "float64[] f\n")
    assert msg_dependencies(text, "pkg") == ["std_msgs/Header", "std_msgs/ColorRGBA",
                                             "pkg/Point", "geometry_msgs/Vector3"]


@settings(max_examples=60, deadline=None)
@given(sec=st.integers(0, 2**31 - 1), nsec=st.integers(0, 999_999_999))
def test_stamp_is_read_from_the_cdr_bytes(sec, nsec):
    m = VehicleState()
    m.header.stamp = Time(sec=sec, nanosec=nsec)
    m.header.frame_id = "map"
    assert cdr_stamp_ns(serialize_message(m)) == sec * 1_000_000_000 + nsec
    assert cdr_stamp_ns(serialize_message(Clock(clock=Time(sec=sec, nanosec=nsec)))) == \
        sec * 1_000_000_000 + nsec


def test_unknown_topic_is_rejected_by_name_and_typed_topics_are_accepted():
    with pytest.raises(ValueError, match="/nope"):
        topic_info("/nope")
    info = topic_info("/extra:std_msgs/String")
    assert info.type == "std_msgs/msg/String"


# -- written bag read back independently -------------------------------------------------------
def test_bag_reads_back_whole_with_rosbags_reader_and_anyreader(tmp_path):
    from rosbags.highlevel import AnyReader
    from rosbags.interfaces import QosDurability
    from rosbags.rosbag2 import Reader

    folder = tmp_path / "bag"
    written = write_run_bag(folder, steps=120)
    assert sorted(p.name for p in folder.iterdir()) == ["bag_0.mcap", "metadata.yaml"]
    total = sum(len(v) for v in written.values())
    with Reader(folder) as r:
        assert r.message_count == total
        counts = {c.topic: c.msgcount for c in r.connections}
        assert counts == {t: len(v) for t, v in written.items()}
        by_topic = {c.topic: c for c in r.connections}
        assert by_topic["/reference/trajectory"].ext.offered_qos_profiles[0].durability == \
            QosDurability.TRANSIENT_LOCAL
        assert by_topic["/vehicle/state"].ext.offered_qos_profiles[0].depth == 1000
        logged = [(c.topic, t) for c, t, _ in r.messages()]
    expected_order = sorted((t, topic) for topic, v in written.items() for t, _ in v)
    assert [t for _, t in logged] == [t for t, _ in expected_order]

    with AnyReader([folder]) as r:
        got: dict[str, list] = {t: [] for t in written}
        for c, _t, raw in r.messages():
            got[c.topic].append(r.deserialize(raw, c.msgtype))
    for k, m in enumerate(got["/vehicle/state"]):
        src = written["/vehicle/state"][k][1]
        assert (m.header.stamp.sec, m.header.stamp.nanosec) == (src.header.stamp.sec,
                                                                src.header.stamp.nanosec)
        for f in ("x", "y", "yaw", "vx", "vy", "yaw_rate", "sideslip", "steer_front"):
            assert getattr(m, f) == getattr(src, f)
        for f in ("wheel_speed", "fz", "mu"):
            np.testing.assert_array_equal(getattr(m, f), np.asarray(getattr(src, f)))
    for k, m in enumerate(got["/control/mpc_diagnostics"]):
        src = written["/control/mpc_diagnostics"][k][1]
        assert (m.controller, m.np, m.nc, m.q_y, m.solver_status, m.iterations, m.fallback) == \
            (src.controller, src.np, src.nc, src.q_y, src.solver_status, src.iterations,
             src.fallback)
    assert got["/vehicle/odom"][5].pose.pose.position.x == 5.0
    np.testing.assert_array_equal(got["/reference/trajectory"][0].x, reference().x)
    assert json.loads(got["/run/status"][-1].data)["state"] == "ended"
    assert [m.clock.nanosec for m in got["/clock"]][:3] == [0, DT_NS, 2 * DT_NS]


def test_bare_mcap_reads_with_anyreader_and_metadata_is_rosbag2_v9(tmp_path):
    from rosbags.highlevel import AnyReader

    folder = tmp_path / "bag"
    written = write_run_bag(folder, steps=30)
    with AnyReader([folder / "bag_0.mcap"]) as r:
        n = sum(1 for _ in r.messages())
    assert n == sum(len(v) for v in written.values())
    meta = yaml.safe_load((folder / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
    assert meta["version"] == 9 and meta["storage_identifier"] == "mcap"
    assert meta["relative_file_paths"] == ["bag_0.mcap"]
    assert meta["message_count"] == n
    assert meta["custom_data"]["fourws_state"] == "complete"
    first = min(t for v in written.values() for t, _ in v)
    last = max(t for v in written.values() for t, _ in v)
    assert meta["starting_time"]["nanoseconds_since_epoch"] == first
    assert meta["duration"]["nanoseconds"] == last - first
    tm = {t["topic_metadata"]["name"]: t for t in meta["topics_with_message_count"]}
    assert tm["/vehicle/state"]["topic_metadata"]["type_description_hash"] == type_hash(
        "fourws_msgs/msg/VehicleState")


def test_mcap_file_has_ros2_profile_schemas_channels_and_stamps_as_publish_time(tmp_path):
    from mcap.reader import make_reader

    folder = tmp_path / "bag"
    write_run_bag(folder, steps=20)
    with open(folder / "bag_0.mcap", "rb") as fh:
        reader = make_reader(fh)
        assert reader.get_header().profile == "ros2"
        summary = reader.get_summary()
        assert {s.encoding for s in summary.schemas.values()} == {"ros2msg"}
        assert {c.message_encoding for c in summary.channels.values()} == {"cdr"}
        ch = next(c for c in summary.channels.values() if c.topic == "/vehicle/state")
        assert "offered_qos_profiles" in ch.metadata and ch.metadata["topic_type_hash"]
        assert all(ci.compression == "zstd" for ci in summary.chunk_indexes)
        assert len(summary.chunk_indexes) > 1
        for _s, c, m in reader.iter_messages(topics=["/vehicle/state", "/run/status"]):
            if c.topic == "/vehicle/state":
                assert m.publish_time == cdr_stamp_ns(m.data)
            else:
                assert m.publish_time == m.log_time


def test_read_run_gives_per_step_arrays_from_run_or_bag_folder_or_mcap(tmp_path):
    write_run_bag(tmp_path / "bag", steps=50, republish=True)
    runs = [read_run(p) for p in (tmp_path, tmp_path / "bag", tmp_path / "bag" / "bag_0.mcap")]
    for run in runs:
        s = run.state
        assert run.steps == 50
        np.testing.assert_array_equal(s["stamp_ns"], np.arange(50) * DT_NS)
        np.testing.assert_array_equal(s["x"], np.arange(50.0))  # first of each stamp kept
        assert s["wheel_speed"].shape == (50, 4)
        np.testing.assert_array_equal(s["fz"][:, 0], 1800.0 + np.arange(50))
        d = run.mpc_diagnostics
        np.testing.assert_array_equal(d["np"], 12 + np.arange(50) % 9)
        assert d["fallback"].dtype == bool and d["fallback"][0] and not d["fallback"][1]
        assert d["solver_status"][0] == "solved" and run.controller == "improved"
        np.testing.assert_allclose(run.mpc_command["yaw_moment"], 10.0 * np.arange(50))
        assert run.wheel_torques["torque"].shape == (50, 4)
        assert run.wheel_torques["allocation"][0] == "optimal"
        assert len(run.drive_command["stamp_ns"]) == 0
        np.testing.assert_array_equal(run.reference["x"], reference().x)
        assert run.status["state"] == "ended" and run.scenario == "dlc"
        assert run.message_counts["/vehicle/state"] == 55


def test_read_run_sorts_by_stamp_and_keeps_the_first_of_each_stamp(tmp_path):
    w = BagWriter(tmp_path / "b", [topic_info("/vehicle/state")])
    for i, (k, x) in enumerate([(2, 20.0), (0, 0.0), (1, 10.0), (1, 99.0), (2, 98.0)]):
        w.write("/vehicle/state", serialize_message(vehicle_state(k, x=x)), 1000 + i)
    w.close()
    run = read_run(tmp_path / "b")
    np.testing.assert_array_equal(run.state["stamp_ns"], [0, DT_NS, 2 * DT_NS])
    np.testing.assert_array_equal(run.state["x"], [0.0, 10.0, 20.0])
    np.testing.assert_array_equal(run.state["log_ns"], [1001, 1002, 1000])  # the first's


def test_step_latencies_are_the_receive_time_differences_along_the_chain(tmp_path):
    """write_run_bag logs one message per µs, per step: clock, state, odom, MPC command,
    diagnostics, torques. Each stage is then 2 µs and the step 6 µs; no drive command."""
    write_run_bag(tmp_path / "bag", steps=40)
    run = read_run(tmp_path / "bag")
    assert np.all(np.diff(run.state["log_ns"]) == 6000)
    lat = step_latencies_ms(run)
    assert set(lat) == {"state_to_mpc_command", "mpc_command_to_wheel_torques",
                        "wheel_torques_to_next_state", "step"}
    for stage in ("state_to_mpc_command", "mpc_command_to_wheel_torques",
                  "wheel_torques_to_next_state"):
        assert lat[stage] == pytest.approx({"p50": 0.002, "p90": 0.002})
    assert lat["step"] == pytest.approx({"p50": 0.006, "p90": 0.006})
    lat_sum = sum(lat[k]["p50"] for k in lat if k != "step")
    assert lat_sum == pytest.approx(lat["step"]["p50"])


def test_writer_refuses_a_non_empty_output_folder(tmp_path):
    (tmp_path / "b").mkdir()
    (tmp_path / "b" / "x").write_text("x")
    with pytest.raises(ValueError, match="output_dir"):
        BagWriter(tmp_path / "b", [topic_info("/vehicle/state")])


def test_metadata_at_start_and_after_each_chunk_counts_what_is_on_disk(tmp_path):
    folder = tmp_path / "b"
    w = BagWriter(folder, [topic_info("/vehicle/state")], chunk_size_bytes=4096)
    meta = yaml.safe_load((folder / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
    assert meta["message_count"] == 0 and meta["custom_data"]["fourws_state"] == "recording"
    flushed_at = []
    for k in range(100):
        if w.write("/vehicle/state", serialize_message(vehicle_state(k)), 1000 + k):
            flushed_at.append(k + 1)
    assert flushed_at
    meta = yaml.safe_load((folder / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
    assert meta["message_count"] == flushed_at[-1]
    size_before_close = w.path.stat().st_size
    w.close()
    w.close()  # idempotent
    assert w.path.stat().st_size > size_before_close
    meta = yaml.safe_load((folder / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
    assert meta["message_count"] == 100


# -- damaged files -----------------------------------------------------------------------------
def _chunks(path: Path) -> list[tuple[int, int, int]]:
    """(start, end, message count) of each chunk, from the file's own index."""
    from mcap.reader import make_reader

    with open(path, "rb") as fh:
        summary = make_reader(fh).get_summary()
    return [(ci.chunk_start_offset, ci.chunk_start_offset + ci.chunk_length,
             _count_in_chunk(path, ci)) for ci in
            sorted(summary.chunk_indexes, key=lambda c: c.chunk_start_offset)]


def _count_in_chunk(path: Path, ci) -> int:
    from mcap.data_stream import ReadDataStream
    from mcap.records import Chunk, Message
    from mcap.stream_reader import breakup_chunk

    with open(path, "rb") as fh:
        fh.seek(ci.chunk_start_offset + 9)
        chunk = Chunk.read(ReadDataStream(fh))
    return sum(isinstance(r, Message) for r in breakup_chunk(chunk))


def _messages(path: Path) -> list[tuple[str, int, bytes]]:
    from mcap.reader import make_reader

    with open(path, "rb") as fh:
        return [(c.topic, m.log_time, m.data) for _s, c, m in
                make_reader(fh).iter_messages(log_time_order=False)]


def test_truncated_file_raises_bag_error_naming_the_file(tmp_path):
    write_run_bag(tmp_path / "run" / "bag", steps=120)
    mcap = tmp_path / "run" / "bag" / "bag_0.mcap"
    data = mcap.read_bytes()
    mcap.write_bytes(data[: len(data) // 2])
    for p in (tmp_path / "run", tmp_path / "run" / "bag", mcap):
        with pytest.raises(BagError) as info:
            read_run(p)
        text = str(info.value)
        assert str(mcap) in text and "truncated" in text and "fourws bag recover" in text


def test_not_an_mcap_and_missing_paths_raise_bag_error(tmp_path):
    bad = tmp_path / "x.mcap"
    bad.write_bytes(b"hello world, not a bag at all" * 5)
    with pytest.raises(BagError, match="not an MCAP"):
        read_run(bad)
    with pytest.raises(BagError, match="no such"):
        read_run(tmp_path / "missing")
    (tmp_path / "empty").mkdir()
    with pytest.raises(BagError, match="no .mcap"):
        read_run(tmp_path / "empty")


def test_corrupt_chunk_raises_bag_error_naming_the_file(tmp_path):
    write_run_bag(tmp_path / "bag", steps=120)
    mcap = tmp_path / "bag" / "bag_0.mcap"
    start, end, _n = _chunks(mcap)[1]
    data = bytearray(mcap.read_bytes())
    mid = (start + end) // 2
    data[mid:mid + 16] = bytes(16)
    mcap.write_bytes(bytes(data))
    with pytest.raises(BagError) as info:
        read_run(mcap)
    assert str(mcap) in str(info.value)


@pytest.mark.parametrize("fraction", [0.3, 0.5, 0.8])
def test_recover_keeps_every_complete_chunk_of_a_truncated_file(tmp_path, fraction):
    from rosbags.highlevel import AnyReader

    write_run_bag(tmp_path / "bag", steps=150)
    full = tmp_path / "bag" / "bag_0.mcap"
    chunks = _chunks(full)
    assert len(chunks) >= 4
    original = _messages(full)
    cut = int(full.stat().st_size * fraction)
    expected = sum(n for _s, e, n in chunks if e <= cut)
    truncated = tmp_path / "cut.mcap"
    shutil.copyfile(full, truncated)
    with open(truncated, "r+b") as fh:
        fh.truncate(cut)
    fixed = tmp_path / "fixed.mcap"
    n = recover(truncated, fixed)
    assert n == expected > 0
    assert _messages(fixed) == original[:n]
    with AnyReader([fixed]) as r:
        decoded = [r.deserialize(raw, c.msgtype) for c, _t, raw in r.messages()]
    assert len(decoded) == n
    run = read_run(fixed)
    assert run.steps > 0
    np.testing.assert_array_equal(run.state["x"], np.arange(run.steps, dtype=float))


def test_recover_of_a_whole_file_keeps_everything(tmp_path):
    written = write_run_bag(tmp_path / "bag", steps=40)
    n = recover(tmp_path / "bag", tmp_path / "copy.mcap")
    assert n == sum(len(v) for v in written.values())
    assert _messages(tmp_path / "copy.mcap") == _messages(tmp_path / "bag" / "bag_0.mcap")


def test_bag_qos_table_matches_the_graph_profiles():
    from fourws_common.qos import CLOCK_QOS, CONTROL_QOS, LATCHED_QOS
    from fourws_common.topics import QOS_KINDS

    for kind, profile in (("control", CONTROL_QOS), ("latched", LATCHED_QOS),
                          ("clock", CLOCK_QOS)):
        assert QOS_KINDS[kind].depth == profile.depth, kind
        assert QOS_KINDS[kind].durability == profile.durability.name.lower(), kind
        assert QOS_KINDS[kind].reliability == profile.reliability.name.lower(), kind


def test_rejection_counts_from_diagnostics_reach_the_metrics(tmp_path):
    """What the nodes publish on /diagnostics (cumulative counts per kind) is in the run's
    metrics: the highest count each node reported, only nodes that rejected something."""
    from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue

    from fourws_bringup.scoring import bag_metrics

    write_run_bag(tmp_path / "bag", steps=30)
    w = BagWriter(tmp_path / "diag", [topic_info("/diagnostics")])
    for t, (mpc, pid) in enumerate(((0, 0), (1, 0), (3, 0))):
        msg = DiagnosticArray()
        msg.status = [
            DiagnosticStatus(name="/mpc_node", values=[KeyValue(key="future_stamp",
                                                                value=str(mpc))]),
            DiagnosticStatus(name="/speed_pid_node", values=[KeyValue(key="implausible_state",
                                                                      value=str(pid))])]
        w.write("/diagnostics", serialize_message(msg), 1000 + t)
    w.close()
    run = read_run(tmp_path / "diag")
    assert run.rejections == {"mpc_node": {"future_stamp": 3},
                              "speed_pid_node": {"implausible_state": 0}}
    full = read_run(tmp_path / "bag")
    assert bag_metrics(full)["input_rejections"] == {}
    full.rejections = run.rejections
    assert bag_metrics(full)["input_rejections"] == {"mpc_node": {"future_stamp": 3}}


def test_strays_in_a_row_never_become_the_runs_timeline():
    """Two stray states 10 ms apart, stamped 1000 s ahead, among a run of 1044 (issue 41,
    item 3: they had been taken for the run's new timeline, and 99 056 steps counted
    missing): the run's timeline stays the plant's, the strays are counted apart; a state
    that arrives late, within the jump limit, stays on the timeline."""
    from fourws_bringup.bag.run_data import drop_strays

    step = 10_000_000
    plant = [(k * step, k, None) for k in range(1044)]
    strays = [(1000 * 10**9, -1, None), (1000 * 10**9 + step, -2, None)]
    rows = plant[:100] + strays + plant[100:]
    kept, n = drop_strays(rows)
    assert kept == plant and n == 2
    late = plant[:50] + plant[51:60] + [plant[50]] + plant[60:]
    kept, n = drop_strays(late)
    assert n == 0 and sorted(kept) == plant
    far_past = [(-5 * 10**9, -3, None)]
    kept, n = drop_strays(plant[:10] + far_past + plant[10:])
    assert kept == plant and n == 1
    # a node that paused for 2 s (a realtime stall) answers again 200 steps later: both
    # stretches are the run's, not strays
    paused = plant[:110] + plant[310:]
    kept, n = drop_strays(paused)
    assert kept == paused and n == 0


def test_a_chunk_is_completed_once_it_spans_its_time_limit(tmp_path):
    """Issue 41, item 8: a killed recorder lost its first ~1.5 s (one 256 kB chunk). With
    chunk_max_span_ns a chunk is completed once its messages span that much log time, so
    a file cut where it stands loses at most that span: recovered, it holds every message
    older than about 1 s before the cut."""
    folder = tmp_path / "b"
    step = 10_000_000
    w = BagWriter(folder, [topic_info("/vehicle/state")], chunk_size_bytes=64 * 2**20,
                  chunk_max_span_ns=10**9)
    completed = [k for k in range(350)
                 if w.write("/vehicle/state", serialize_message(vehicle_state(k)), k * step)]
    # every 1 s of log time (101 messages: the one that reaches the span closes its chunk),
    # not once 64 MB are buffered
    assert completed == [100, 201, 302]
    cut = tmp_path / "cut.mcap"
    shutil.copyfile(w.path, cut)                  # the file as a kill would leave it
    w.close()
    assert recover(cut, tmp_path / "fixed.mcap") == 303
    assert read_run(tmp_path / "fixed.mcap").state["stamp_ns"].size == 303
