"""The whole fourws graph: plant, MPC (or lqr_ff), speed PID, allocator, optionally the recorder.

    ros2 launch fourws_bringup fourws.launch.py scenario:=dlc_60_mu05 controller:=improved
    ros2 launch fourws_bringup fourws.launch.py record:=true bag:=runs/car1 namespace:=car1
    ros2 launch fourws_bringup fourws.launch.py --show-args

The same node table as ``fourws run`` (fourws_bringup.launching; docs/graph.md, "Launch"). The
launch ends when the plant ends: exit 0 when it completed the scenario, 1 otherwise (the
plant's code is logged).
"""

from fourws_bringup.launching import fourws_launch_description


def generate_launch_description():
    return fourws_launch_description()
