"""fourws the way a ROS user starts it: ``ros2 launch`` with the real launch and ros2cli.

The real ``ros2`` command and ``launch`` come from ``../shared/ros2-tools`` (built on top of
the project's venv, ``ros_ws/ros2tools``); where that folder is absent these tests skip,
saying so. Nothing in fourws needs it at run time: a user's ROS install has these tools.

- ``fourws.launch.py`` in lockstep records the same run as ``fourws run`` (same bag
  contents, same metrics) and ends with the plant: exit 0 when the plant completed;
- Ctrl-C (SIGINT to the launch's process group, as a terminal sends it) stops every node
  cleanly (the plant with its "interrupted" code, 130) and leaves a readable bag;
- a bad argument ends the launch with exit 1 and a message naming it;
- ``controllers.launch.py`` in a namespace drives a plant in that namespace to the end of
  its scenario (the control stack on "your own plant").
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import time
from pathlib import Path

import pytest
from conftest import cut_scenario, pid_alive

from fourws_bringup.bag.run_data import read_run
from fourws_bringup.supervisor import NodeSpec
from fourws_common.exit_codes import RUN_END_CODES
from fourws_common.resources import config_dir

pytestmark = [pytest.mark.integration, pytest.mark.slow]

ROOT = Path(__file__).resolve().parents[2]
TOOLS = Path(os.environ.get("FOURWS_ROS2_TOOLS", ROOT.parent / "shared" / "ros2-tools"))


@pytest.fixture(scope="module")
def ros2_env() -> Path:
    """The env.sh of the real ros2/launch tools, built once into ros_ws/ros2tools."""
    build = TOOLS / "build.sh"
    if not build.is_file():
        pytest.skip(f"the real ros2 command line and launch are not here ({build} is absent; "
                    "set FOURWS_ROS2_TOOLS to the ros2-tools folder): launch tests need them")
    prefix = ROOT / "ros_ws" / "ros2tools"
    env_sh = prefix / "env.sh"
    if not (prefix / "bin" / "ros2").exists() or not env_sh.is_file():
        r = subprocess.run(["bash", str(build), str(prefix)], cwd=ROOT, capture_output=True,
                           text=True, timeout=900)
        assert r.returncode == 0, f"ros2-tools build failed:\n{r.stdout[-3000:]}{r.stderr[-3000:]}"
    return env_sh


def _launch(env_sh: Path, domain_id: int, file: str, *args: str) -> subprocess.Popen:
    """``ros2 launch fourws_bringup FILE ARGS`` in its own process group and domain."""
    cmd = f'source "{env_sh}" && exec ros2 launch fourws_bringup {file} ' + " ".join(
        f"'{a}'" for a in args)
    env = {**os.environ, "ROS_DOMAIN_ID": str(domain_id),
           "ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST"}
    return subprocess.Popen(["bash", "-c", cmd], env=env, stdout=subprocess.PIPE,
                            stderr=subprocess.STDOUT, text=True, start_new_session=True)


def _finish(proc: subprocess.Popen, timeout_s: float) -> str:
    try:
        out, _ = proc.communicate(timeout=timeout_s)
    except subprocess.TimeoutExpired:
        os.killpg(proc.pid, signal.SIGKILL)
        out, _ = proc.communicate()
        pytest.fail(f"ros2 launch did not end within {timeout_s:.0f} s:\n{out[-4000:]}")
    return out


def _descendants(pid: int) -> set[int]:
    """Every live process below ``pid`` (read from /proc)."""
    children: dict[int, list[int]] = {}
    for d in Path("/proc").iterdir():
        if d.name.isdigit():
            try:
                ppid = int((d / "stat").read_text().rsplit(")", 1)[1].split()[1])
            except (OSError, IndexError, ValueError):
                continue
            children.setdefault(ppid, []).append(int(d.name))
    out, todo = set(), [pid]
    while todo:
        for c in children.get(todo.pop(), []):
            if c not in out:
                out.add(c)
                todo.append(c)
    return out


def test_a_lockstep_launch_records_the_same_run_as_fourws_run(ros2_env, domain_id, tmp_path):
    """On the second shipped car (``vehicle:=``, ``--vehicle``): the launch puts every node on
    it as ``fourws run`` does, and both record the same run."""
    from fourws_sim.core.vehicle_params import load_vehicle_params

    scenario = cut_scenario(tmp_path, 60.0)
    out = tmp_path / "run"
    r = subprocess.run(["fourws", "run", "--scenario", str(scenario), "--controller",
                        "mpc_4ws", "--vehicle", "c_segment", "--out", str(out), "--no-plots"],
                       capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, r.stderr[-3000:]
    proc = _launch(ros2_env, domain_id, "fourws.launch.py", f"scenario:={scenario}",
                   "controller:=mpc_4ws", "vehicle:=c_segment", "record:=true",
                   f"bag:={tmp_path / 'launch_bag'}")
    log = _finish(proc, 600.0)
    assert proc.returncode == 0, log[-4000:]
    assert "plant_node ended with exit code 0 (COMPLETED)" in log, log[-4000:]
    assert "has died" not in log and "Traceback" not in log, log[-4000:]
    launched, ran = read_run(tmp_path / "launch_bag"), read_run(out)
    assert launched.steps == ran.steps > 300
    car = load_vehicle_params("c_segment")
    assert launched.state["fz"][0].sum() == pytest.approx(car.mass_kg * car.gravity_mps2,
                                                          rel=0.02)
    for key in ("x", "y", "yaw", "vx", "vy", "yaw_rate"):
        assert launched.state[key].tolist() == ran.state[key].tolist(), key
    for key in ("delta_front", "delta_rear", "yaw_moment"):
        assert launched.mpc_command[key].tolist() == ran.mpc_command[key].tolist(), key
    rep = tmp_path / "report"
    subprocess.run(["fourws", "report", str(tmp_path / "launch_bag"), "--out", str(rep)],
                   check=True, capture_output=True, timeout=300)
    m_launch = json.loads((rep / "metrics.json").read_text())
    m_run = json.loads((out / "metrics.json").read_text())
    for key in ("max_abs_lateral_error_m", "rmse_lateral_error_m", "max_abs_sideslip_deg",
                "steps"):
        assert m_launch[key] == m_run[key], key


def test_ctrl_c_stops_every_node_cleanly(ros2_env, domain_id, ros, tmp_path):
    """Realtime mode (the plant paces itself), recorder on; SIGINT to the whole process group
    once the plant is publishing: every process ends, none dies, the bag is whole."""
    from std_msgs.msg import String

    from fourws_common.qos import LATCHED_QOS

    # /run/status heartbeats (not a per-step topic: the plant does not count this
    # subscriber among those it waits for)
    sim_s: list[float] = [0.0]
    ros.node.create_subscription(
        String, "/run/status",
        lambda m: sim_s.append(float(json.loads(m.data).get("sim_time_s", 0.0))), LATCHED_QOS)
    bag = tmp_path / "bag"
    proc = _launch(ros2_env, domain_id, "fourws.launch.py", "mode:=realtime",
                   "controller:=improved", "record:=true", f"bag:={bag}")
    try:
        assert ros.spin_until(lambda: sim_s[-1] > 2.0, 120.0), "the graph never ran"
        below = _descendants(proc.pid)
        assert len(below) >= 5, below  # ros2 launch, plant, MPC, PID, allocator, recorder
        os.killpg(proc.pid, signal.SIGINT)
        log = _finish(proc, 60.0)
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
    deadline = time.monotonic() + 10.0
    while any(pid_alive(p) for p in below) and time.monotonic() < deadline:
        time.sleep(0.1)
    assert not [p for p in below if pid_alive(p)], "a process outlived the launch"
    assert "Traceback" not in log, log[-4000:]
    # The plant ends with its documented code for a run stopped before its end (130,
    # fourws_common.exit_codes; launch words every non-zero code "died"); every other node
    # ends with 0.
    died = [ln for ln in log.splitlines() if "process has died" in ln]
    assert len(died) == 1 and "[plant_node-" in died[0] and "exit code 130" in died[0], died
    assert "plant_node ended with exit code 130 (INTERRUPTED)" in log, log[-3000:]
    for node in ("mpc_node", "speed_pid_node", "allocator_node", "recorder_node"):
        assert f"[{node}-" in log and f"[{node}-" in "".join(
            ln for ln in log.splitlines() if "process has finished cleanly" in ln), node
    assert proc.returncode == 1  # ros2 launch: 0 only for a plant that completed its run
    run = read_run(bag)
    assert run.steps > 100 and (bag / "metadata.yaml").is_file()
    # realtime starts as lockstep does (issue 41, item 9): step 1 after the answers to step 0
    assert run.state["stamp_ns"][1] == 10_000_000
    assert run.mpc_command["stamp_ns"][0] == 0 == run.wheel_torques["stamp_ns"][0]
    assert run.state["wall_ns"][1] >= max(run.mpc_command["wall_ns"][0],
                                          run.wheel_torques["wall_ns"][0])


@pytest.mark.parametrize(("args", "names"), [
    (("controller:=no_such_preset",), ("no_such_preset",)),
    (("mode:=fast",), ("mode", "fast")),
    (("record:=true",), ("bag:=",)),
    (("condition:=no_such_condition",), ("condition", "no_such_condition")),
    (("scenario:=nosuch",), ("scenario", "nosuch")),
    (("condition:=realistic", "seed:=abc"), ("seed", "abc", "integer")),
    (("seed:=3",), ("seed", "condition:=")),
    (("vehicle:=no_such_car",), ("vehicle", "no_such_car", "c_segment")),
])
def test_a_bad_argument_ends_the_launch_with_a_clear_error(ros2_env, domain_id, args, names):
    proc = _launch(ros2_env, domain_id, "fourws.launch.py", *args)
    log = _finish(proc, 120.0)
    assert proc.returncode != 0, log[-3000:]
    for n in names:
        assert n in log, (n, log[-3000:])
    assert "process started" not in log, ("nodes were started", log[-3000:])


@pytest.mark.parametrize("file", ["fourws.launch.py", "controllers.launch.py"])
def test_show_args_names_every_preset_and_where_the_clock_goes(ros2_env, domain_id, file):
    """Issue 41, item 9: ``--show-args`` omitted improved_np30 and said /clock stays global,
    where a namespaced simulation moves it (graph.clock_remap)."""
    from fourws_bringup.core.configs import list_controllers

    proc = _launch(ros2_env, domain_id, file, "--show-args")
    text = _finish(proc, 120.0)
    assert proc.returncode == 0, text[-3000:]
    flat = " ".join(text.split())
    from fourws_common.vehicle_info import list_vehicles

    for name in list_controllers() + list_vehicles():
        assert name in flat, (name, flat[-3000:])
    assert "/clock moves with it" in flat and "(/clock and /diagnostics stay global)" not in flat


def test_the_control_stack_alone_drives_a_plant_in_its_namespace(ros2_env, domain_id, graph,
                                                               tmp_path):
    """``controllers.launch.py namespace:=car3 sync:=lockstep`` and a plant started by hand in
    /car3: the plant completes its (short) scenario on the launched controllers' commands."""
    scenario = cut_scenario(tmp_path, 40.0)
    status = tmp_path / "status.json"
    proc = _launch(ros2_env, domain_id, "controllers.launch.py", "controller:=mpc_4ws",
                   "namespace:=car3", "sync:=lockstep")
    try:
        sup = graph([NodeSpec("plant_node", "fourws_sim", "plant_node",
                              params_files=[str(config_dir("fourws_sim") / "plant.yaml")],
                              parameters={"scenario": str(scenario), "status_file": str(status),
                                          "wait_for_subscribers": 3,
                                          "wait_for_reference_subscribers": 3},
                              end_codes=RUN_END_CODES, namespace="car3")], timeout_s=60.0)
        plant = sup.procs["plant_node"].popen
        plant.wait(timeout=300)
        assert plant.returncode == 0, sup.procs["plant_node"].last_lines()
        result = json.loads(status.read_text())
        assert result["completed"] and result["steps"] > 200, result
    finally:
        os.killpg(proc.pid, signal.SIGINT)
        log = _finish(proc, 60.0)
    assert "has died" not in log and "Traceback" not in log, log[-4000:]
    for node in ("mpc_node", "speed_pid_node", "allocator_node"):
        assert f"[{node}-" in log, node


def test_ros2_param_describe_shows_the_choices_of_a_string_parameter(ros2_env, domain_id,
                                                                     graph):
    """String choices are in the descriptor's additional_constraints, which ``ros2 param
    describe`` prints as "Constraints"; numeric ranges as the allowed range."""
    graph([NodeSpec("mpc_node", "fourws_mpc", "mpc_node",
                    params_files=[str(config_dir("fourws_mpc") / "mpc.yaml")])])
    env = {**os.environ, "ROS_DOMAIN_ID": str(domain_id),
           "ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST"}
    # no daemon (none is left behind); wait for the node, not a fixed time
    r = subprocess.run(["bash", "-c", f'source "{ros2_env}" && ros2 param describe '
                        "--no-daemon --spin-time 5 --timeout 120 /mpc_node weights_mode np_max"],
                       env=env, capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, (r.stdout[-2000:], r.stderr[-2000:])
    text = r.stdout
    assert "Constraints:" in text and "fixed" in text and "fuzzy" in text, text
    assert "Min value:" in text and "Max value:" in text, text


def test_respawn_brings_a_killed_mpc_back_and_the_run_completes(ros2_env, domain_id, ros,
                                                                 tmp_path):
    """respawn:=true, lockstep: kill -9 the MPC once the plant is running; launch starts it
    again, the plant's safe hold bridges the gap, and the run completes."""
    from std_msgs.msg import String

    from fourws_common.qos import LATCHED_QOS

    sim_s: list[float] = [0.0]
    ros.node.create_subscription(
        String, "/run/status",
        lambda m: sim_s.append(float(json.loads(m.data).get("sim_time_s", 0.0))), LATCHED_QOS)
    scenario = cut_scenario(tmp_path, 60.0)
    proc = _launch(ros2_env, domain_id, "fourws.launch.py", f"scenario:={scenario}",
                   "mode:=realtime", "controller:=mpc_4ws", "respawn:=true")
    try:
        assert ros.spin_until(lambda: sim_s[-1] > 1.0, 120.0), "the graph never ran"
        mpc = [p for p in _descendants(proc.pid)
               if "mpc_node" in Path(f"/proc/{p}/cmdline").read_bytes().decode(errors="ignore")
               and "python" in Path(f"/proc/{p}/cmdline").read_bytes().decode(errors="ignore")]
        assert mpc, "no MPC process"
        for p in mpc:
            os.kill(p, signal.SIGKILL)
        log = _finish(proc, 300.0)
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
    assert "[mpc_node-" in log and "process has died" in log, log[-3000:]
    assert log.count("[mpc_node-") > 1 and "Traceback" not in log, log[-4000:]
    assert "plant_node ended with exit code 0 (COMPLETED)" in log, log[-4000:]
    assert proc.returncode == 0, log[-3000:]
