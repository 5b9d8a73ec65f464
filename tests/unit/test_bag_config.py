"""recorder.yaml and replay.yaml load into the nodes' config dataclasses and mirror their
defaults; bad values are rejected naming the parameter."""

from __future__ import annotations

import dataclasses

import pytest

from fourws_common.params import from_mapping, load_ros_params_yaml
from fourws_common.resources import config_dir
from fourws_common.topics import DEFAULT_TOPICS, topic_info

pytest.importorskip("rclpy")
from fourws_bringup.recorder_node import RecorderConfig  # noqa: E402
from fourws_bringup.replay_node import ReplayConfig  # noqa: E402


def test_recorder_yaml_mirrors_the_defaults_and_lists_every_graph_topic():
    values = load_ros_params_yaml(str(config_dir("fourws_bringup") / "recorder.yaml"),
                                  "recorder_node")
    topics = values.pop("topics")
    assert tuple(topics) == DEFAULT_TOPICS
    assert all(topic_info(t).name == t for t in topics)
    assert set(values) == {f.name for f in dataclasses.fields(RecorderConfig)} - {"output_dir"}
    cfg = from_mapping(RecorderConfig, {**values, "output_dir": "x"})
    assert cfg == RecorderConfig(output_dir="x")


def test_replay_yaml_mirrors_the_defaults():
    values = load_ros_params_yaml(str(config_dir("fourws_bringup") / "replay.yaml"),
                                  "replay_node")
    assert set(values) == {f.name for f in dataclasses.fields(ReplayConfig)} - {"bag"}
    assert from_mapping(ReplayConfig, {**values, "bag": "b"}) == ReplayConfig(bag="b")


@pytest.mark.parametrize(("cls", "values", "name"), [
    (RecorderConfig, {}, "output_dir"),
    (RecorderConfig, {"output_dir": "x", "compression": "gzip"}, "compression"),
    (RecorderConfig, {"output_dir": "x", "chunk_size_bytes": 100}, "chunk_size_bytes"),
    (RecorderConfig, {"output_dir": "x", "drain_quiet_s": 5.0, "drain_max_s": 1.0},
     "drain_quiet_s"),
    (ReplayConfig, {}, "bag"),
    (ReplayConfig, {"bag": "b", "rate": -1.0}, "rate"),
    (ReplayConfig, {"bag": "b", "pacing": "wall"}, "pacing"),
])
def test_bad_values_name_the_parameter(cls, values, name):
    with pytest.raises(ValueError, match=name):
        from_mapping(cls, values)


def test_a_recorder_keeps_the_diagnostics_of_its_own_namespace_only():
    """/diagnostics is one topic for every graph of a domain: the recorder of /car1 keeps
    /car1's statuses, drops an array of /car2's, and trims a mixed one; at the root it keeps
    the root's nodes (issue 41, item 10)."""
    from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
    from rclpy.serialization import deserialize_message, serialize_message

    from fourws_bringup.recorder_node import own_diagnostics

    def array(*names):
        return serialize_message(DiagnosticArray(
            status=[DiagnosticStatus(name=n) for n in names]))

    car1 = own_diagnostics("/car1")
    mine = array("/car1/mpc_node", "/car1/mpc_node: runtime")
    assert car1(mine) == mine
    assert car1(array("/car2/mpc_node", "/car2/mpc_node: runtime")) is None
    trimmed = deserialize_message(car1(array("/car1/plant_node", "/car2/plant_node")),
                                  DiagnosticArray)
    assert [s.name for s in trimmed.status] == ["/car1/plant_node"]
    root = own_diagnostics("/")
    assert root(array("/mpc_node")) is not None and root(array("/car1/mpc_node")) is None
