"""Test node: relays /chatter_cmd to /relayed_cmd, doubling delta_front."""

from rclpy.node import Node

from fourws_common.node_main import run_node
from fourws_msgs.msg import MpcCommand


class Relay(Node):
    def __init__(self) -> None:
        super().__init__("relay")
        self.pub = self.create_publisher(MpcCommand, "relayed_cmd", 10)
        self.create_subscription(MpcCommand, "chatter_cmd", self.on_cmd, 10)

    def on_cmd(self, msg: MpcCommand) -> None:
        msg.delta_front *= 2.0
        self.pub.publish(msg)


def main() -> None:
    raise SystemExit(run_node(Relay))


if __name__ == "__main__":
    main()
