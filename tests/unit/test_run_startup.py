"""What keeps a run's start-up and stop short (no DDS): the Fast DDS profiles the supervisor
gives every node, the fast exit after a node's clean-up, the recorder's start gate."""

from __future__ import annotations

import os
import subprocess
import sys
import xml.etree.ElementTree as ET
from pathlib import Path

from fourws_bringup.graph import graph_specs
from fourws_bringup.supervisor import (
    DDS_PROFILES_ENV,
    DDS_PROFILES_FILE,
    NodeSpec,
    Supervisor,
    dds_environment,
)

NS = "{http://www.eprosima.com/XMLSchemas/fastRTPS_Profiles}"


def test_the_nodes_get_the_shipped_fast_dds_profiles_unless_the_user_has_their_own(
        tmp_path, monkeypatch):
    for own in ("FASTRTPS_DEFAULT_PROFILES_FILE", "FASTDDS_DEFAULT_PROFILES_FILE"):
        monkeypatch.delenv(own, raising=False)
    env = dds_environment({})
    path = env[DDS_PROFILES_ENV]
    assert path.endswith(DDS_PROFILES_FILE)
    root = ET.parse(path).getroot()
    beat = root.find(f"{NS}data_writer/{NS}times/{NS}heartbeatPeriod")
    assert beat is not None and float(beat.find(f"{NS}sec").text) == 0.0
    assert 0 < int(beat.find(f"{NS}nanosec").text) <= 200_000_000    # Fast DDS: 3 s
    assert all(p.get("is_default_profile") == "true" for p in root)
    for own in ("FASTRTPS_DEFAULT_PROFILES_FILE", "FASTDDS_DEFAULT_PROFILES_FILE"):
        assert dds_environment({own: str(tmp_path / "mine.xml")}) == {}
    sup = Supervisor([NodeSpec("talker", "fourws_bringup", "talker")], 7, tmp_path,
                     env={"FASTRTPS_DEFAULT_PROFILES_FILE": "theirs.xml"})
    assert sup.env[DDS_PROFILES_ENV] == "theirs.xml"
    sup = Supervisor([NodeSpec("talker", "fourws_bringup", "talker")], 7, tmp_path)
    assert sup.env[DDS_PROFILES_ENV] == path and sup.env["FOURWS_FAST_EXIT"] == "1"


def _recorder(specs: list[NodeSpec]) -> NodeSpec:
    return next(s for s in specs if s.name == "recorder_node")


def test_the_start_gate_has_no_settle_time_where_every_writer_waits_for_the_recorder(tmp_path):
    """Recorded lockstep runs: every controller answers only once its outputs have matched
    the recorder, so the gate's 0.5 s settle time is not needed; elsewhere it stays."""
    lockstep = _recorder(graph_specs("dlc_60_mu05", "improved", tmp_path / "bag"))
    assert lockstep.parameters["start_gate_settle_s"] == 0.0
    assert lockstep.parameters["start_gate_topic"] == "/vehicle/state"
    for other in (graph_specs("dlc_60_mu05", "improved", tmp_path / "bag", mode="realtime"),
                  graph_specs("dlc_60_mu05", "improved", tmp_path / "bag", via_adapter=True)):
        assert "start_gate_settle_s" not in _recorder(other).parameters


def test_fast_exit_flushes_the_output_and_keeps_the_exit_code():
    code = ("import sys; from fourws_common.fast_exit import exit_now; "
            "print('last words', end=''); sys.stderr.write('err'); exit_now(3)")
    src = Path(__file__).resolve().parents[2] / "src" / "fourws_common"
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(
        filter(None, [str(src), os.environ.get("PYTHONPATH", "")]))}
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         timeout=60, env=env)
    assert (out.returncode, out.stdout, out.stderr) == (3, "last words", "err")
