"""The one ``main()`` shape every fourws node uses (Jazzy: ``rclpy.init`` is no context manager)."""

from __future__ import annotations

import sys
from collections.abc import Callable

import rclpy
from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
from rclpy.node import Node


def run_node(factory: Callable[[], Node], args: list[str] | None = None) -> int:
    """Init rclpy, build the node, spin until shutdown, clean up. Returns an exit code.

    A ``ValueError`` raised while building the node (a bad parameter) is reported in one line
    and gives exit code 2, so a supervisor can show why the node did not start.
    """
    rclpy.init(args=args)
    node = None
    code = 0
    try:
        node = factory()
        executor = SingleThreadedExecutor()
        executor.add_node(node)
        # A node that ends by itself (the plant at the end of a scenario) sets ``done``.
        while rclpy.ok() and not getattr(node, "done", False):
            executor.spin_once(timeout_sec=0.1)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    except ValueError as exc:
        print(f"[fatal] {exc}", file=sys.stderr, flush=True)
        code = 2
    finally:
        if node is not None:
            code = getattr(node, "exit_code", code) or code
            node.destroy_node()
        rclpy.try_shutdown()
    return code
