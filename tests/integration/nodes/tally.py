"""Test node: takes /chatter_cmd (reliable) and, when destroyed, writes the highest count it
received to its parameter ``out_file`` ("none" if it got nothing)."""

from pathlib import Path

from rclpy.node import Node

from fourws_common.node_main import run_node
from fourws_msgs.msg import MpcCommand


class Tally(Node):
    def __init__(self) -> None:
        super().__init__("tally")
        self.highest: int | None = None
        self.out_file = self.declare_parameter("out_file", "").value
        self.create_subscription(MpcCommand, "chatter_cmd", self.take, 1000)

    def take(self, msg: MpcCommand) -> None:
        self.highest = max(self.highest or 0, int(msg.delta_front))

    def destroy_node(self) -> None:
        Path(self.out_file).write_text(f"{self.highest if self.highest is not None else 'none'}\n")
        super().destroy_node()


def main() -> None:
    raise SystemExit(run_node(Tally))


if __name__ == "__main__":
    main()
