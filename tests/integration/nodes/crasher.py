"""Test node: joins the graph, logs a line, then exits with code 3 after a short while."""

import sys
import time

import rclpy

rclpy.init()
node = rclpy.create_node("crasher")
node.get_logger().info("crasher up; about to fail on purpose")
delay_s = float(sys.argv[1]) if len(sys.argv) > 1 and sys.argv[1][0].isdigit() else 2.0
end = time.monotonic() + delay_s
while time.monotonic() < end:
    rclpy.spin_once(node, timeout_sec=0.05)
print("crasher: simulated fault", flush=True)
sys.exit(3)
