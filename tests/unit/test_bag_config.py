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
