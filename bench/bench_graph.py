"""Cost of the ROS graph itself: one DDS hop between two rclpy processes, and a full run.

Usage: python bench/bench_graph.py [OUT.json]   (default bench/results_graph.json)

1. ``hop``: round trip of a small stamped message (MpcCommand, CONTROL_QOS) between two
   rclpy processes with the nodes' executor (EventsExecutor), 2 000 round trips after 100
   warm-up ones; half the median round trip is the floor of one stage of the lockstep chain
   (state → MPC → allocator → plant: three stages a step) on this machine, before any
   computation.
2. ``runs``: ``fourws run`` of improved on dlc_60_mu05 in lockstep with the recorder, once in
   each process layout (``--compose none``, ``control``, ``all``; interleaved, ``ROUNDS``
   rounds, since this shared machine's speed drifts within minutes): the real-time factor,
   the MPC step inside the node and ``step_latency_ms`` (per chain stage, from the bag).
3. ``end_to_end``: the wall time of ``fourws run`` with its default options (report and
   plots), as a user sees it, once per round;
4. ``in_process``: the same run in the in-process loop (``run_closed_loop``, the same cores
   the graph reproduces), in the same rounds, so each layout's RTF is compared with the
   in-process RTF of the same minutes (``rtf_ratio``: median graph RTF / median in-process).

Both run in a domain of their own (the supervisor's DomainLease). Needs the built
workspace (``source ros_ws/env.sh``).
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import tempfile
import textwrap
import time
from pathlib import Path

import numpy as np

N_ROUND_TRIPS = 2_000
N_WARMUP = 100
LAYOUTS = ("none", "control", "all")
ROUNDS = 2

ECHO = textwrap.dedent("""
    import sys, time
    import rclpy
    import rclpy.executors
    from rclpy.experimental import EventsExecutor
    from fourws_common.qos import CONTROL_QOS
    from fourws_msgs.msg import MpcCommand
    rclpy.init()
    node = rclpy.create_node("bench_echo")
    pub = node.create_publisher(MpcCommand, "/bench/pong", CONTROL_QOS)
    node.create_subscription(MpcCommand, "/bench/ping", pub.publish, CONTROL_QOS)
    ex = EventsExecutor()
    ex.add_node(node)
    end = time.monotonic() + float(sys.argv[1])
    try:
        while time.monotonic() < end and rclpy.ok():
            ex.spin_once(timeout_sec=0.1)
    except (KeyboardInterrupt, rclpy.executors.ExternalShutdownException):
        pass
""")


def bench_hop() -> dict:
    import rclpy
    from rclpy.experimental import EventsExecutor

    from fourws_common.qos import CONTROL_QOS
    from fourws_msgs.msg import MpcCommand

    echo = subprocess.Popen([sys.executable, "-c", ECHO, "120"])  # noqa: S603
    rclpy.init()
    try:
        node = rclpy.create_node("bench_ping")
        pub = node.create_publisher(MpcCommand, "/bench/ping", CONTROL_QOS)
        got: list[int] = []
        node.create_subscription(MpcCommand, "/bench/pong",
                                 lambda _m: got.append(time.perf_counter_ns()), CONTROL_QOS)
        ex = EventsExecutor()
        ex.add_node(node)
        deadline = time.monotonic() + 60.0
        while pub.get_subscription_count() < 1 or node.count_publishers("/bench/pong") < 1:
            if time.monotonic() > deadline:
                raise RuntimeError("the echo process never matched")
            ex.spin_once(timeout_sec=0.05)
        rtt = []
        for i in range(N_WARMUP + N_ROUND_TRIPS):
            n, t0 = len(got), time.perf_counter_ns()
            pub.publish(MpcCommand(delta_front=float(i)))
            while len(got) == n:
                ex.spin_once(timeout_sec=1.0)
            if i >= N_WARMUP:
                rtt.append((got[-1] - t0) * 1e-3)
        r = np.asarray(rtt)
        return {"round_trips": len(r), "round_trip_us_median": float(np.median(r)),
                "round_trip_us_p90": float(np.percentile(r, 90)),
                "round_trip_us_p99": float(np.percentile(r, 99)),
                "stage_floor_ms": float(np.median(r)) * 0.5e-3}
    finally:
        echo.terminate()
        echo.wait(10)
        rclpy.try_shutdown()


def bench_run(layout: str) -> dict:
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "run"
        cmd = ["fourws", "run", "--scenario", "dlc_60_mu05", "--controller", "improved",
               "--out", str(out), "--no-plots", "--compose", layout]
        subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL,  # noqa: S603
                       stderr=subprocess.DEVNULL)
        m = json.loads((out / "metrics.json").read_text())
    keys = ("steps", "sim_time_s", "wall_time_s", "real_time_factor", "mpc_solve_ms_p50",
            "mpc_solve_ms_p99", "missing_steps", "step_latency_ms")
    return {"run": "improved@dlc_60_mu05", "compose": layout, **{k: m.get(k) for k in keys}}


def bench_end_to_end() -> dict:
    """Wall time of ``fourws run`` as a user types it (default options: report and plots
    included), from the command's start to its exit."""
    with tempfile.TemporaryDirectory() as tmp:
        cmd = ["fourws", "run", "--scenario", "dlc_60_mu05", "--controller", "improved",
               "--out", str(Path(tmp) / "run")]
        t0 = time.perf_counter()
        subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL,  # noqa: S603
                       stderr=subprocess.DEVNULL)
        return {"run": "improved@dlc_60_mu05", "wall_s": time.perf_counter() - t0}


def bench_in_process() -> dict:
    """Wall time of the in-process loop on the same run: the ``run_closed_loop`` call alone
    (its set-up included), as the graph's RTF counts from the plant's first answered state.
    The compiled kernels are loaded from their cache first (a 3-step run), as every node
    loads them before its first input (``laws.warm_up``, ``Simulator.warm_up``)."""
    code = textwrap.dedent("""
        import json, sys, time
        import fourws_common
        from fourws_bringup.core.closed_loop import run_closed_loop
        run_closed_loop("dlc_60_mu05", "improved", max_steps=3)
        t0 = time.perf_counter()
        log = run_closed_loop("dlc_60_mu05", "improved")
        wall = time.perf_counter() - t0
        sim = log.steps * 0.01
        print(json.dumps({"steps": log.steps, "sim_time_s": sim, "wall_time_s": wall,
                          "real_time_factor": sim / wall}))
    """)
    r = subprocess.run([sys.executable, "-c", code], check=True, capture_output=True,  # noqa: S603
                       text=True)
    return {"run": "improved@dlc_60_mu05", "compose": "in_process",
            **json.loads(r.stdout.strip().splitlines()[-1])}


def main(out: str) -> int:
    from fourws_bringup.supervisor import DomainLease

    lease = DomainLease()
    os.environ["ROS_DOMAIN_ID"] = str(lease.domain_id)
    try:
        hop = bench_hop()
        print(f"hop: round trip median {hop['round_trip_us_median']:.0f} µs "
              f"(p90 {hop['round_trip_us_p90']:.0f}): {hop['stage_floor_ms']:.2f} ms per stage")
    finally:
        lease.release()
    runs, in_process, end_to_end = [], [], []
    for _ in range(ROUNDS):
        e2e = bench_end_to_end()
        end_to_end.append(e2e)
        print(f"fourws run, end to end: {e2e['wall_s']:.2f} s")
        ip = bench_in_process()
        in_process.append(ip)
        print(f"in-process loop: RTF {ip['real_time_factor']:.2f}")
        for layout in LAYOUTS:
            run = bench_run(layout)
            runs.append(run)
            lat = run.get("step_latency_ms") or {}
            print(f"run --compose {layout:7s}: RTF {run['real_time_factor']:.2f}, step median "
                  f"{lat.get('step', {}).get('p50', float('nan')):.2f} ms, MPC step in the "
                  f"node median {run['mpc_solve_ms_p50']:.2f} ms")
    ip_rtf = float(np.median([r["real_time_factor"] for r in in_process]))
    ratio = {layout: float(np.median([r["real_time_factor"] for r in runs
                                      if r["compose"] == layout])) / ip_rtf
             for layout in LAYOUTS}
    print("graph RTF / in-process RTF: " + ", ".join(f"{k} {v:.2f}" for k, v in ratio.items()))
    Path(out).write_text(json.dumps({"hop": hop, "runs": runs, "in_process": in_process,
                                     "in_process_rtf_median": ip_rtf, "rtf_ratio": ratio,
                                     "end_to_end": end_to_end},
                                    indent=2) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1] if len(sys.argv) > 1 else "bench/results_graph.json"))
