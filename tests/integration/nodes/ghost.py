"""Test program: runs but never creates a ROS node, so it never appears in the graph."""

import time

while True:
    time.sleep(0.1)
