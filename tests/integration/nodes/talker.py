"""Test node: publishes fourws_msgs/MpcCommand on /chatter_cmd at 50 Hz, counting up.

Parameter ``out_file``: where to write the last count sent when the node is destroyed.
"""

from pathlib import Path

from rclpy.node import Node

from fourws_common.node_main import run_node
from fourws_msgs.msg import MpcCommand


class Talker(Node):
    def __init__(self) -> None:
        super().__init__("talker")
        self.pub = self.create_publisher(MpcCommand, "chatter_cmd", 10)
        self.n = 0
        self.out_file = self.declare_parameter("out_file", "").value
        self.create_timer(0.02, self.tick)

    def tick(self) -> None:
        self.n += 1
        self.pub.publish(MpcCommand(delta_front=float(self.n), yaw_moment=0.5 * self.n))

    def destroy_node(self) -> None:
        if self.out_file:
            Path(self.out_file).write_text(f"{self.n}\n")
        super().destroy_node()


def main() -> None:
    raise SystemExit(run_node(Talker))


if __name__ == "__main__":
    main()
