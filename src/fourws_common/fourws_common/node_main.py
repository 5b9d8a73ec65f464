"""The one ``main()`` shape every fourws node uses (Jazzy: ``rclpy.init`` is no context manager).

Signals (docs/graph.md, "Timing"): SIGINT and SIGTERM request a stop: the executor's loop ends
after the callback it is in, then every node is destroyed and rclpy shut down, in that order.
A node may install its own handlers in its constructor (the recorder drains first).

Before a node is destroyed, each of its reliable publishers gets up to ``STOP_ACK_TIMEOUT_S``
(in all) for its samples to be acknowledged by every matched reader: a sample lost on the
loopback is re-sent only while its writer lives. The supervisor stops a recorder after the
writers it records (``NodeSpec.stop_stage``).

Executor: rclpy's ``EventsExecutor`` (``rclpy.experimental``, in Jazzy) by default; the
``SingleThreadedExecutor`` spends much of its CPU rebuilding its wait set on every
``spin_once``. Set ``FOURWS_EXECUTOR=single`` to fall back to the stable executor.

Exit: the executor is shut down before the nodes are destroyed (it holds their handles), so
each node, and the process's DDS participant with the last one, is destroyed then and the
other processes see it leave at once. With ``FOURWS_FAST_EXIT=1`` (the supervisor sets it for
the processes it starts) the process then ends with :func:`fourws_common.fast_exit.exit_now`
(output flushed, ``os._exit``). Without it (a node run by hand, ``ros2 launch``, a test
in-process) the process exits as usual.

Profiling: with ``FOURWS_PROFILE=DIR`` each process profiles its executor thread with
cProfile from the first node built to shutdown and writes ``DIR/<node names>.<pid>.prof``
(read with ``python -m pstats``); off by default (it slows the callbacks).
"""

from __future__ import annotations

import os
import signal
import sys
import time
from collections.abc import Callable, Sequence

import rclpy
from rclpy.clock import Clock, ClockType
from rclpy.duration import Duration
from rclpy.exceptions import ParameterException
from rclpy.executors import Executor, ExternalShutdownException, SingleThreadedExecutor
from rclpy.experimental import EventsExecutor
from rclpy.node import Node
from rclpy.signals import SignalHandlerOptions
from rclpy.task import Future

from fourws_common.fast_exit import exit_now
from fourws_common.ros_params import check_overrides

#: Environment variable that picks the executor: ``events`` (default) or ``single``.
EXECUTOR_ENV = "FOURWS_EXECUTOR"
EXECUTORS: dict[str, Callable[[], Executor]] = {
    "events": EventsExecutor,
    "single": SingleThreadedExecutor,
}
#: Environment variable naming a folder for per-process cProfile output (module docstring).
PROFILE_ENV = "FOURWS_PROFILE"
#: Environment variable: ``1`` ends the process with ``os._exit`` after the clean-up
#: (module docstring, "Exit").
FAST_EXIT_ENV = "FOURWS_FAST_EXIT"
#: Wall period (s, steady clock) at which ``run_nodes`` checks whether a node has set ``done``.
DONE_POLL_PERIOD_S = 0.02
#: Longest wait (s, in all) at shutdown for a node's reliable samples to be acknowledged.
STOP_ACK_TIMEOUT_S = 2.0
#: Housekeeping topics not waited for at shutdown: their last samples are no part of a run's
#: record (in a container process the /diagnostics writers went unacknowledged for the whole
#: 2 s while the recorder was up, and every composed run's stop took 2 s longer).
NO_ACK_WAIT_TOPICS = frozenset({"/diagnostics", "/rosout", "/parameter_events"})


def make_executor(name: str | None = None) -> Executor:
    """The executor named by ``name`` or ``$FOURWS_EXECUTOR`` (default ``events``)."""
    name = name or os.environ.get(EXECUTOR_ENV, "events")
    try:
        return EXECUTORS[name]()
    except KeyError:
        raise ValueError(
            f"{EXECUTOR_ENV}={name!r} is not an executor; use one of {sorted(EXECUTORS)}"
        ) from None


def run_node(factory: Callable[[], Node], args: list[str] | None = None) -> int:
    """Init rclpy, build the node, spin until shutdown, clean up. Returns an exit code.

    A ``ValueError`` raised while building the node (a bad, wrongly typed or unknown
    parameter) is reported in one line and gives exit code 2 (``ExitCode.BAD_CONFIG``), so a
    supervisor can show why the node did not start.
    """
    return run_nodes([factory], args)


def run_nodes(factories: Sequence[Callable[[], Node]], args: list[str] | None = None) -> int:
    """Several nodes in one process and one executor (a component container's job).

    The nodes stay separate rclpy nodes with their own names, parameters and topics; they only
    share the process, the DDS participant and the executor thread, so a message between two
    of them takes no inter-process hop. Spins until shutdown or until any node sets ``done``;
    the exit code is the first non-zero ``exit_code`` of a node, 2 for a bad parameter.
    """
    rclpy.init(args=args, signal_handler_options=SignalHandlerOptions.NO)
    # A stop request ends the loop between callbacks (module docstring); installed before
    # the nodes are built, so a node's own handlers replace it.
    stop = Future()

    def on_signal(_signum, _frame) -> None:
        if not stop.done():
            stop.set_result(True)

    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, on_signal)
    nodes: list[Node] = []
    code = 0
    profiler = _start_profiler()
    try:
        executor = make_executor()
        for factory in factories:
            nodes.append(factory())
            check_overrides(nodes[-1], args)
            executor.add_node(nodes[-1])
    except (ValueError, ParameterException) as exc:  # start-up: a bad parameter or file
        print(f"[fatal] {exc}", file=sys.stderr, flush=True)
        for node in nodes:
            node.destroy_node()
        rclpy.try_shutdown()
        return 2
    try:
        # A node that ends by itself (the plant at the end of a scenario) sets ``done``; a
        # steady-clock timer notices it, so the executor's loop runs in C++ without a return
        # to Python after every callback (spin_once costs ~13 µs more per callback).
        def poll_done() -> None:
            if not stop.done() and any(getattr(n, "done", False) for n in nodes):
                stop.set_result(True)

        nodes[0].create_timer(DONE_POLL_PERIOD_S, poll_done,
                              clock=Clock(clock_type=ClockType.STEADY_TIME))
        while rclpy.ok() and not stop.done():
            executor.spin_until_future_complete(stop, timeout_sec=1.0)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    except Exception as exc:  # noqa: BLE001 - a runtime error: say it in one line, exit 1
        print(f"[fatal] {type(exc).__name__}: {exc}", file=sys.stderr, flush=True)
        code = 1
    finally:
        # Stopping now: a further SIGINT has nothing left to ask. Ignored, it cannot kill the
        # process while it closes (Python resets its own handlers to the default while the
        # interpreter finalises; ``ros2 launch`` sends SIGINT again to every process still
        # running after a Ctrl-C, which killed a node with -2). SIGTERM still ends it.
        signal.signal(signal.SIGINT, signal.SIG_IGN)
        for node in nodes:
            code = code or getattr(node, "exit_code", 0) or 0
        _stop_profiler(profiler, [n.get_name() for n in nodes])
        wait_for_acks(nodes, STOP_ACK_TIMEOUT_S)
        # The executor holds its nodes' handles: shut down first, each node is destroyed now
        # (and the process's DDS participant with the last one, so the others see it leave
        # at once), not when the interpreter collects the executor at exit.
        try:
            executor.shutdown()
        except Exception:  # noqa: BLE001 - nothing to release then
            pass
        for node in nodes:
            node.destroy_node()
        rclpy.try_shutdown()
    if os.environ.get(FAST_EXIT_ENV) == "1":
        exit_now(code)
    return code


def wait_for_acks(nodes: Sequence[Node], timeout_s: float) -> bool:
    """Wait up to ``timeout_s`` (in all) until every reliable publisher of ``nodes`` has its
    samples acknowledged by every matched reader; say on stderr which did not. True if all did.

    A reader that leaves the graph is unmatched and no longer waited for; best-effort
    publishers return at once (``Publisher.wait_for_all_acked``); the housekeeping topics of
    ``NO_ACK_WAIT_TOPICS`` are not waited for.
    """
    deadline = time.monotonic() + timeout_s
    late: list[str] = []
    for node in nodes:
        for pub in list(node.publishers):
            if pub.topic_name in NO_ACK_WAIT_TOPICS:
                continue
            left = max(0.0, deadline - time.monotonic())
            try:
                if not pub.wait_for_all_acked(Duration(seconds=left)):
                    late.append(pub.topic_name)
            except Exception:  # noqa: BLE001 - the context is already shut down: nothing to wait
                return False
    if late:
        print(f"[warn] samples on {', '.join(late)} not acknowledged by every reader within "
              f"{timeout_s:.1f} s of the stop", file=sys.stderr, flush=True)
    return not late


def _start_profiler():
    """A running ``cProfile.Profile`` when ``$FOURWS_PROFILE`` names a folder, else None."""
    if not os.environ.get(PROFILE_ENV):
        return None
    import cProfile

    profiler = cProfile.Profile()
    profiler.enable()
    return profiler


def _stop_profiler(profiler, names: list[str]) -> None:
    """Write the profile to ``$FOURWS_PROFILE/<names>.<pid>.prof``; a write error is said,
    never raised (the run's own exit code stands)."""
    if profiler is None:
        return
    profiler.disable()
    from pathlib import Path

    path = Path(os.environ[PROFILE_ENV]) / f"{'+'.join(names) or 'none'}.{os.getpid()}.prof"
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        profiler.dump_stats(str(path))
    except OSError as exc:
        print(f"[warn] profile not written to {path}: {exc}", file=sys.stderr, flush=True)
