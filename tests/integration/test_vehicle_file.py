"""One car file read by every node (issue 41, "One car file"): the controller nodes take the
car's constants as their parameter defaults, a params file still wins, a bad car stops a
node at start naming the key, and ``fourws run --vehicle`` puts the whole graph on the car.

Outcomes come from the nodes' parameter services (answered while the node runs), a process's
exit status and the run's bag and metrics.json, never from a message of an exiting process.
"""

from __future__ import annotations

import json
import subprocess

import pytest
import yaml
from conftest import cut_scenario

from fourws_bringup.bag.run_data import read_run
from fourws_bringup.graph import graph_specs
from fourws_bringup.supervisor import NodeDied, NodeSpec, last_error_line
from fourws_common.exit_codes import ExitCode
from fourws_common.vehicle_info import load_vehicle_info, read_vehicle_file
from fourws_sim.core.vehicle_params import load_vehicle_params

pytestmark = pytest.mark.integration
CAR = "c_segment"


def _controllers(**params) -> list[NodeSpec]:
    specs = [s for s in graph_specs("dlc_60_mu05", "improved", None, "lockstep")
             if s.name != "plant_node"]
    for s in specs:
        s.parameters.update(params)
    return specs


def _get(ros, node: str, names: list[str]) -> list:
    from rcl_interfaces.srv import GetParameters
    from rclpy.parameter import parameter_value_to_python

    cli = ros.node.create_client(GetParameters, f"/{node}/get_parameters")
    assert ros.spin_until(cli.service_is_ready, 30), f"{node}: no parameter service"
    fut = cli.call_async(GetParameters.Request(names=names))
    assert ros.spin_until(fut.done, 30)
    return [parameter_value_to_python(v) for v in fut.result().values]


def test_every_controller_node_takes_the_cars_constants(graph, ros, tmp_path):
    info = load_vehicle_info(CAR)
    override = tmp_path / "mismatch.yaml"    # a mismatch study: the MPC is told 1500 kg
    override.write_text(yaml.safe_dump({"mpc_node": {"ros__parameters": {"mass_kg": 1500.0}}}))
    specs = _controllers(vehicle_file=CAR)
    next(s for s in specs if s.name == "mpc_node").params_files.append(str(override))
    graph(specs)
    mass, iz, track, c_f = _get(ros, "mpc_node", ["mass_kg", "yaw_inertia_kg_m2",
                                                  "track_width_m",
                                                  "cornering_stiffness_front_static_n_per_rad"])
    assert (mass, iz, c_f) == (1500.0, info.yaw_inertia_kg_m2,
                               info.cornering_stiffness_front_static_n_per_rad)
    assert track == pytest.approx(info.track_width_m)
    assert _get(ros, "speed_pid_node", ["mass_kg", "max_total_torque_nm"]) == [
        info.mass_kg, 4 * info.motor_torque_max_nm]
    assert _get(ros, "allocator_node", ["mass_kg", "wheel_radius_m", "vehicle_file"]) == [
        info.mass_kg, info.wheel_radius_m, CAR]
    # the car is read at start: another car at runtime is refused, the same one accepted
    assert not _set(ros, "mpc_node", "vehicle_file", "paper").successful
    assert _set(ros, "mpc_node", "vehicle_file", CAR).successful
    assert _get(ros, "mpc_node", ["yaw_inertia_kg_m2"]) == [info.yaw_inertia_kg_m2]


def _set(ros, node: str, name: str, value):
    from rcl_interfaces.srv import SetParameters
    from rclpy.parameter import Parameter

    cli = ros.node.create_client(SetParameters, f"/{node}/set_parameters")
    assert ros.spin_until(cli.service_is_ready, 30)
    fut = cli.call_async(SetParameters.Request(
        parameters=[Parameter(name, value=value).to_parameter_msg()]))
    assert ros.spin_until(fut.done, 30)
    return fut.result().results[0]


def test_a_car_file_that_does_not_load_stops_the_node_naming_the_key(graph, tmp_path):
    raw = read_vehicle_file()
    raw.pop("cg_height_m")
    bad = tmp_path / "bad_car.yaml"
    bad.write_text(yaml.safe_dump(raw))
    sup = graph([s for s in _controllers(vehicle_file=str(bad)) if s.name == "allocator_node"],
                start=False)
    try:
        sup.start(timeout_s=30)
        rc = sup.wait_exit("allocator_node", timeout_s=30)
    except NodeDied as exc:        # it may exit before or after the graph probe saw it
        rc = exc.returncode
    assert rc == ExitCode.BAD_CONFIG
    error = last_error_line(sup.procs["allocator_node"].last_lines())
    assert "cg_height_m" in error and "bad_car.yaml" in error, error


def test_fourws_run_on_another_car(tmp_path):
    """The plant carries the car (its static wheel loads sum to the car's weight), metrics.json
    names the car file and its hash, and the run completes on the car."""
    scenario = cut_scenario(tmp_path, 60.0)
    out = tmp_path / "run"
    r = subprocess.run(["fourws", "run", "--scenario", str(scenario), "--controller",
                        "improved", "--vehicle", CAR, "--out", str(out), "--no-plots",
                        "--compose", "all"], capture_output=True, text=True, timeout=300)
    m = json.loads((out / "metrics.json").read_text())
    assert r.returncode == ExitCode.COMPLETED == m["exit_code"], r.stderr[-2000:]
    assert m["vehicle_file"].endswith(f"vehicles/{CAR}.yaml") and len(m["vehicle_sha256"]) == 64
    car = load_vehicle_params(CAR)
    fz = read_run(out).state["fz"][0]           # oracle tyre data of the first state
    assert fz.sum() == pytest.approx(car.mass_kg * car.gravity_mps2, rel=0.02)


def test_fourws_run_refuses_a_bad_car_before_any_node_starts(tmp_path):
    r = subprocess.run(["fourws", "run", "--scenario", "dlc_60_mu05", "--controller",
                        "improved", "--vehicle", "no_such_car", "--out", str(tmp_path / "r")],
                       capture_output=True, text=True, timeout=60)
    assert r.returncode == ExitCode.BAD_CONFIG
    assert "no_such_car" in r.stderr and "c_segment" in r.stderr
    assert len(r.stderr.strip().splitlines()) == 1, r.stderr
    assert not (tmp_path / "r").exists()
