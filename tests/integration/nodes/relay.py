"""Test node: relays /chatter_cmd to /relayed_cmd, doubling delta_front."""

import rclpy
from rclpy.executors import ExternalShutdownException
from rclpy.node import Node

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
    rclpy.init()
    node = None
    try:
        node = Relay()
        rclpy.spin(node)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        if node is not None:
            node.destroy_node()
        rclpy.try_shutdown()


if __name__ == "__main__":
    main()
