"""The fourws control stack alone (MPC, speed PID, allocator), for your own plant or simulator.

    ros2 launch fourws_bringup controllers.launch.py controller:=improved namespace:=car1
    ros2 launch fourws_bringup controllers.launch.py --show-args

It subscribes vehicle/state and reference/trajectory and publishes control/mpc_command,
control/drive_command and control/wheel_torques (docs/controller-interface.md). The same
nodes and parameters as in ``fourws run`` (fourws_bringup.launching; docs/graph.md, "Launch").
"""

from fourws_bringup.launching import controllers_launch_description


def generate_launch_description():
    return controllers_launch_description()
