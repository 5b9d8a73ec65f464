"""Where an in-process control step's time goes: the loop's stages and the MPC step's
largest functions (docs/graph.md, "Timing"; docs/mpc.md, "Benchmark").

Usage: python bench/profile_loop.py [CONTROLLER] [SCENARIO]   (default improved dlc_60_mu05)

Runs the closed loop of ``fourws_bringup.core.closed_loop`` three times (one BLAS thread)
with each stage's call timed by ``time.perf_counter`` (the fastest run is shown), then once
under cProfile, which lists the MPC's largest functions by their own time in µs per step as
profiled (a compiled or C call is inflated little, Python glue more). Not part of ``make
bench``: a diagnosis, not a figure.
"""

from __future__ import annotations

import contextlib
import cProfile
import pstats
import sys
import time
from collections import defaultdict

import _src_path  # noqa: F401 - the checkout's sources first


def main(argv: list[str]) -> int:
    from threadpoolctl import threadpool_limits

    from fourws_bringup.core.closed_loop import run_closed_loop

    controller = argv[0] if argv else "improved"
    scenario = argv[1] if len(argv) > 1 else "dlc_60_mu05"
    with threadpool_limits(1):
        run_closed_loop(scenario, controller, max_steps=50)          # kernels loaded
        runs = []
        for _ in range(3):
            with _stage_timers() as spent:
                t0 = time.perf_counter()
                log = run_closed_loop(scenario, controller)
                runs.append((time.perf_counter() - t0, dict(spent)))
        prof = cProfile.Profile()
        prof.enable()
        run_closed_loop(scenario, controller)
        prof.disable()
    whole, spent = min(runs, key=lambda r: r[0])
    n = log.steps
    sim_s = float(log.state["t_s"][-1] - log.state["t_s"][0]) * n / max(n - 1, 1)
    print(f"{controller} on {scenario}: {n} steps, {whole / n * 1e3:.3f} ms per step "
          f"(real-time factor {sim_s / whole:.1f}; stage timers included)")
    for label, s in sorted(spent.items(), key=lambda kv: -kv[1]):
        print(f"  {label:12s} {s / n * 1e3:.3f} ms ({100 * s / whole:.0f} %)")
    rest = whole - sum(spent.values())
    print(f"  {'the rest':12s} {rest / n * 1e3:.3f} ms ({100 * rest / whole:.0f} %: logging, "
          "the end check, set-up)")
    stats = pstats.Stats(prof).stats
    mpc = sorted(((v[2], k) for k, v in stats.items()
                  if "fourws_mpc" in k[0] or "daqp" in k[0] or "osqp" in k[0]), reverse=True)
    print("  the MPC's largest functions, own time per step (profiled):")
    for own, (path, _, name) in mpc[:12]:
        print(f"    {own / n * 1e6:6.1f} µs  {path.rsplit('/', 1)[-1]}:{name}")
    return 0


@contextlib.contextmanager
def _stage_timers():
    """The loop's stage methods wrapped by timers while the block runs (restored after):
    yields {stage: seconds}."""
    from fourws_bringup.core import closed_loop as cl

    spent: dict[str, float] = defaultdict(float)

    def timed(label, fn):
        def call(*args, **kwargs):
            t0 = time.perf_counter()
            try:
                return fn(*args, **kwargs)
            finally:
                spent[label] += time.perf_counter() - t0
        return call

    make = cl.make_controller

    def make_timed(cfg):
        ctrl = make(cfg)
        ctrl.step = timed("MPC step", ctrl.step)
        return ctrl

    patched = [(cl.Simulator, "step", "plant step"), (cl.TorqueAllocator, "allocate",
               "allocation"), (cl.SpeedPid, "step", "speed PID")]
    saved = [(cls, name, cls.__dict__[name]) for cls, name, _ in patched]
    try:
        cl.make_controller = make_timed
        for cls, name, label in patched:
            setattr(cls, name, timed(label, getattr(cls, name)))
        yield spent
    finally:
        cl.make_controller = make
        for cls, name, fn in saved:
            setattr(cls, name, fn)


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
