"""`fourws run` with bad input: an existing output folder, a node that dies, a bad scenario."""

from __future__ import annotations

import json
import subprocess

import pytest
import yaml

pytestmark = pytest.mark.integration


def _fourws(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run(["fourws", *args], capture_output=True, text=True, timeout=300)


def test_existing_output_folder_is_not_overwritten_without_force(tmp_path):
    out = tmp_path / "run"
    out.mkdir()
    keep = out / "precious.txt"
    keep.write_text("do not delete")
    r = _fourws("run", "--scenario", "dlc_60_mu05", "--controller", "improved",
                "--out", str(out))
    assert r.returncode == 2
    assert str(out) in r.stderr and "--force" in r.stderr
    assert keep.read_text() == "do not delete"


def test_unknown_controller_and_overdemanding_scenario_are_clear_errors(tmp_path):
    r = _fourws("run", "--scenario", "dlc_60_mu05", "--controller", "nope",
                "--out", str(tmp_path / "a"))
    assert r.returncode == 2 and "unknown controller 'nope'" in r.stderr
    bad = tmp_path / "too_hard.yaml"
    bad.write_text(yaml.safe_dump({
        "name": "too_hard", "speed_kmh": 90.0, "road": {"type": "constant", "mu": 0.3},
        "path": {"type": "tanh_dlc", "stretch": 1.0}, "duration_s": 5.0}))
    r = _fourws("run", "--scenario", str(bad), "--controller", "improved",
                "--out", str(tmp_path / "b"))
    assert r.returncode == 2 and "μg" in r.stderr


@pytest.mark.parametrize(("compose", "expected"), [
    ("none", "mpc_node"),
    ("control", "control_container (mpc_node, speed_pid_node, allocator_node)"),
    ("all", "node_container (plant_node, mpc_node, speed_pid_node, allocator_node)"),
])
def test_a_node_that_dies_stops_the_run_and_metrics_say_which(tmp_path, compose, expected):
    """A bad MPC parameter kills the process hosting mpc_node at start-up; the run stops,
    keeps its bag folder, and metrics.json names the process (and, for the container, the
    nodes it hosted); the log says which parameter was wrong. (A bad preset is refused before
    any node starts, ``test_cli_files``; the parameter comes here through a condition's
    ``mpc_overrides``, which reach the node as they are.)"""
    condition = tmp_path / "broken.yaml"
    condition.write_text(yaml.safe_dump({"name": "broken", "mpc_overrides": {"q_y": -5.0}}))
    out = tmp_path / "run"
    r = _fourws("run", "--scenario", "dlc_60_mu05", "--controller", "improved",
                "--condition", str(condition), "--out", str(out), "--no-plots",
                "--compose", compose)
    assert r.returncode == 1
    m = json.loads((out / "metrics.json").read_text())
    process = expected.split()[0]
    assert m["completed"] is False and m["died"] == expected
    assert expected in m["reason"]
    assert "q_y" in m["died_error"] and m["exit_code"] == 1  # the node's last error line
    assert m["compose"] == compose
    assert (out / "logs" / f"{process}.log").read_text().count("q_y") >= 1
    assert (out / "bag" / "metadata.yaml").is_file(), "the run's bag folder is kept"
