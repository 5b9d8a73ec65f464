"""FOURWS_PROFILE: a node process profiles its executor thread and writes a pstats file."""

from __future__ import annotations

import pstats

from fourws_common import node_main


def test_profile_is_off_unless_asked(monkeypatch):
    monkeypatch.delenv(node_main.PROFILE_ENV, raising=False)
    assert node_main._start_profiler() is None
    node_main._stop_profiler(None, ["x"])           # nothing to write, nothing raised


def test_profile_written_per_process_and_readable(monkeypatch, tmp_path):
    monkeypatch.setenv(node_main.PROFILE_ENV, str(tmp_path / "prof"))
    prof = node_main._start_profiler()
    sum(i * i for i in range(1000))
    node_main._stop_profiler(prof, ["mpc_node", "plant_node"])
    files = list((tmp_path / "prof").glob("mpc_node+plant_node.*.prof"))
    assert len(files) == 1
    assert pstats.Stats(str(files[0])).total_calls > 0


def test_an_unwritable_profile_is_said_not_raised(monkeypatch, tmp_path, capsys):
    blocker = tmp_path / "file"
    blocker.write_text("x", encoding="utf-8")
    monkeypatch.setenv(node_main.PROFILE_ENV, str(blocker / "sub"))
    node_main._stop_profiler(node_main._start_profiler(), ["n"])
    assert "profile not written" in capsys.readouterr().err
