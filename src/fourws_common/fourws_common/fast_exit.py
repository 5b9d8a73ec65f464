"""End a process at once after its work is done and its output flushed.

A fourws node, once its nodes are destroyed and rclpy is shut down
(:mod:`fourws_common.node_main`, ``FOURWS_FAST_EXIT``), and ``fourws run`` once it has written
its run folder, have nothing left for the interpreter's own teardown, which took 0.15-0.5 s
per process (numba, matplotlib, the middleware's singletons) on the path of every run
(docs/graph.md, "Timing").
"""

from __future__ import annotations

import os
import sys


def exit_now(code: int) -> None:
    """End the process with ``code`` after flushing Python's and C's output buffers; no
    ``atexit`` handler, no ``finally`` block and no other thread runs after this."""
    for stream in (sys.stdout, sys.stderr):
        try:
            stream.flush()
        except Exception:  # noqa: BLE001 - a closed stream has nothing to flush
            pass
    try:
        import ctypes

        ctypes.CDLL(None).fflush(None)
    except Exception:  # noqa: BLE001 - nothing buffered in C then
        pass
    os._exit(code)
