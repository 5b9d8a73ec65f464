"""Test program: two nodes in one process through ``run_nodes``, as a container hosts them.

``finisher`` runs on simulated time with no /clock, so none of its own timers can fire. On
its first message on ``finish`` (fourws_msgs/MpcCommand) it sets ``done`` and takes
``delta_front`` as its exit code: only ``run_nodes``'s steady-clock check can end the process.
``bystander`` is a second, idle node.
"""

from rclpy.node import Node
from rclpy.parameter import Parameter

from fourws_common.node_main import run_nodes
from fourws_msgs.msg import MpcCommand


class Finisher(Node):
    def __init__(self) -> None:
        super().__init__("finisher",
                         parameter_overrides=[Parameter("use_sim_time", value=True)])
        self.done = False
        self.exit_code = 0
        self.create_timer(0.01, self._never)  # sim time without /clock: never fires
        self.create_subscription(MpcCommand, "finish", self._on_finish, 10)

    def _never(self) -> None:
        raise RuntimeError("a sim-time timer fired without /clock")

    def _on_finish(self, msg: MpcCommand) -> None:
        self.exit_code = int(msg.delta_front)
        self.done = True


class Bystander(Node):
    def __init__(self) -> None:
        super().__init__("bystander")


def main() -> None:
    raise SystemExit(run_nodes([Finisher, Bystander]))


if __name__ == "__main__":
    main()
