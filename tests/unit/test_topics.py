"""fourws_common.topics, the one topic/QoS table: its values, the rclpy profiles built from it
(fourws_common.qos) and the nodes taking their topic names from it."""

from __future__ import annotations

import ast
import re
from pathlib import Path

import pytest

from fourws_common.topics import (
    DEFAULT_TOPICS,
    QOS_KINDS,
    TOPICS,
    offered_qos,
    qos_kind,
    topic_info,
)

SRC = Path(__file__).resolve().parents[2] / "src"
#: Files that wire the graph's topics: none of them spells a graph topic name itself.
WIRING = ["fourws_sim/fourws_sim/plant_node.py", "fourws_mpc/fourws_mpc/mpc_node.py",
          "fourws_torque_alloc/fourws_torque_alloc/speed_pid_node.py",
          "fourws_torque_alloc/fourws_torque_alloc/allocator_node.py",
          "fourws_bringup/fourws_bringup/recorder_node.py",
          "fourws_bringup/fourws_bringup/replay_node.py",
          "fourws_common/fourws_common/health.py",
          "fourws_bringup/fourws_bringup/bag/run_data.py",
          "fourws_common/fourws_common/state_input.py",
          "fourws_bringup/fourws_bringup/runner.py", "fourws_bringup/fourws_bringup/report.py"]
#: the QoS profiles a node names itself: the controllers' subscriber-side keep-last-1
#: (reliable in lockstep, best effort with ``sync: latest``)
SUBSCRIBER_SIDE = {"LATEST_QOS", "NEWEST_QOS"}


def test_qos_kinds_keep_their_values():
    got = {k: (q.history, q.depth, q.reliability, q.durability) for k, q in QOS_KINDS.items()}
    assert got == {
        "control": ("keep_last", 1000, "reliable", "volatile"),
        "latched": ("keep_last", 1, "reliable", "transient_local"),
        "clock": ("keep_last", 1000, "reliable", "volatile"),
        "latest": ("keep_last", 1, "reliable", "volatile"),
        "newest": ("keep_last", 1, "best_effort", "volatile"),
        "diagnostics": ("keep_last", 10, "reliable", "volatile"),
    }
    assert all(q.reason for q in QOS_KINDS.values())


def test_every_graph_topic_is_named_typed_and_offers_a_kind_of_the_table():
    assert DEFAULT_TOPICS == (
        "/clock", "/vehicle/state", "/vehicle/ground_truth", "/vehicle/odom", "/vehicle/imu",
        "/vehicle/joint_states", "/reference/trajectory", "/reference/path",
        "/control/mpc_command", "/control/mpc_diagnostics", "/control/drive_command",
        "/control/wheel_torques", "/run/status", "/diagnostics")
    for name, t in TOPICS.items():
        assert t.name == name and name.startswith("/")
        assert re.fullmatch(r"[a-z_]+/msg/[A-Z][A-Za-z]+", t.type), t.type
        assert t.qos in QOS_KINDS and t.qos not in ("latest", "newest"), name  # subscriber side
        assert t.reason
        assert offered_qos(name) == QOS_KINDS[t.qos].as_dict() == topic_info(name).qos


def test_nodes_use_relative_names_but_the_clock_and_diagnostics_stay_global():
    from fourws_common.topics import graph_name, namespace_of

    for name, t in TOPICS.items():
        if name in ("/clock", "/diagnostics"):
            assert t.ros_name == name
        else:
            assert t.ros_name == name[1:] and not t.ros_name.startswith("/")
    assert graph_name("/car1/vehicle/state", "/car1") == "/vehicle/state"
    assert graph_name("/car1/vehicle/state", "car1") == "/vehicle/state"
    assert graph_name("/vehicle/state", "/") == "/vehicle/state"
    assert graph_name("/car1/extra", "/car1") == "/car1/extra"      # not a graph topic
    assert graph_name("/diagnostics", "/car1") == "/diagnostics"
    assert namespace_of(["/diagnostics", "/car1/vehicle/state"]) == "/car1"
    assert namespace_of(["/a/b/vehicle/state"]) == "/a/b"
    assert namespace_of(["/vehicle/state"]) == "/" == namespace_of([])


def test_a_topic_outside_the_table_is_offered_control_qos():
    assert qos_kind("/extra") == "control"
    assert topic_info("/extra:std_msgs/String").qos == QOS_KINDS["control"].as_dict()


def test_rclpy_profiles_are_built_from_the_table_with_the_same_values():
    pytest.importorskip("rclpy")
    from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

    from fourws_common import qos

    def profile(depth, durability=DurabilityPolicy.VOLATILE):
        return QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=depth,
                          reliability=ReliabilityPolicy.RELIABLE, durability=durability)

    assert qos.CONTROL_QOS == profile(1000)
    assert qos.LATCHED_QOS == profile(1, DurabilityPolicy.TRANSIENT_LOCAL)
    assert qos.CLOCK_QOS == profile(1000)
    assert qos.LATEST_QOS == profile(1)
    assert qos.NEWEST_QOS == QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1,
                                        reliability=ReliabilityPolicy.BEST_EFFORT,
                                        durability=DurabilityPolicy.VOLATILE)
    assert qos.DIAGNOSTICS_QOS == profile(10)
    for kind, p in qos.PROFILES.items():
        assert qos.dict_from_profile(p) == QOS_KINDS[kind].as_dict()
        assert qos.profile_from_dict(qos.dict_from_profile(p)) == p
    best_effort_all = {"history": "keep_all", "depth": 0, "reliability": "best_effort",
                       "durability": "volatile"}
    p = qos.profile_from_dict(best_effort_all)
    assert p.depth == 1 and qos.dict_from_profile(p) == {**best_effort_all, "depth": 1}


def _literals(tree: ast.AST) -> set[str]:
    """String constants of a module, docstrings left out."""
    docs = {id(n.body[0].value) for n in ast.walk(tree)
            if isinstance(n, ast.Module | ast.ClassDef | ast.FunctionDef)
            and n.body and isinstance(n.body[0], ast.Expr)
            and isinstance(n.body[0].value, ast.Constant)}
    return {n.value for n in ast.walk(tree) if isinstance(n, ast.Constant)
            and isinstance(n.value, str) and id(n) not in docs}


@pytest.mark.parametrize("path", WIRING)
def test_nodes_take_topic_names_from_the_table(path):
    tree = ast.parse((SRC / path).read_text(encoding="utf-8"))
    assert not _literals(tree) & set(TOPICS), path


@pytest.mark.parametrize("path", WIRING)
def test_nodes_take_each_topics_qos_from_the_table(path):
    """A topic's profile comes from its kind (``qos.qos_of``), never picked by hand."""
    text = (SRC / path).read_text(encoding="utf-8")
    names = {n.id for n in ast.walk(ast.parse(text)) if isinstance(n, ast.Name)}
    hand = {n for n in names if n.endswith("_QOS")} - SUBSCRIBER_SIDE
    assert not hand, f"{path} picks QoS profiles by hand: {sorted(hand)}"
