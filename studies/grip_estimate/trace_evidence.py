#!/usr/bin/env python3
"""One run's μ estimate: its lowest value, max |β|, and the steps around its first evidence
below half the estimate it replaces (studies/grip_estimate/README.md).

    python studies/grip_estimate/trace_evidence.py SCENARIO_YAML --seed N
        [--controller improved] [--ideal-estimated]

Realistic condition with the seed, or with ``--ideal-estimated`` the ideal world with μ
estimated instead of taken from the plant (``mu_from_state: false``). The trace wraps
``GripEstimator.estimate`` to record, per step, the observer's transient slips α̂', the
measured v_y and a_y the MPC saw, μ̂ before the step, the evidence, and the linear tyres'
ask |K_f α̂'f + K_r α̂'r| over μ̂ m g; the plant's true v_y beside them.
"""

from __future__ import annotations

import argparse
import math
import sys

import numpy as np

from fourws_bringup.core.closed_loop import run_closed_loop
from fourws_bringup.core.conditions import IDEAL, load_condition
from fourws_mpc.core import grip
from fourws_mpc.core.model import StateIdx
from fourws_mpc.core.relaxation_model import RelaxIdx


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("scenario")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--controller", default="improved")
    ap.add_argument("--ideal-estimated", action="store_true")
    args = ap.parse_args(argv)
    steps: list[tuple] = []
    estimate = grip.GripEstimator.estimate

    def recorded(self, zeta, ax, ay, mz, mu_state, memory, dt_s):
        est, mem = estimate(self, zeta, ax, ay, mz, mu_state, memory, dt_s)
        p = self.p
        mu_now = self.s.prior if memory is None else memory.mu
        ev = self.evidence(zeta, ax, ay, mz, mu_now) if est.source == "evidence" else None
        ask = 2.0 * (p.c_cf * zeta[RelaxIdx.ALPHA_F] + p.c_cr * zeta[RelaxIdx.ALPHA_R])
        steps.append((math.degrees(zeta[RelaxIdx.ALPHA_F]), math.degrees(zeta[RelaxIdx.ALPHA_R]),
                      float(zeta[StateIdx.VY]), ay, mu_now, ev,
                      abs(ask) / (mu_now * p.mass_kg * p.gravity_mps2)))
        return est, mem

    grip.GripEstimator.estimate = recorded
    try:
        if args.ideal_estimated:
            log = run_closed_loop(args.scenario, args.controller, condition=IDEAL,
                                  mpc_overrides={"mu_from_state": False})
        else:
            log = run_closed_loop(args.scenario, args.controller,
                                  condition=load_condition("realistic", args.seed))
    finally:
        grip.GripEstimator.estimate = estimate
    mu = np.asarray(log.mpc["mu_estimate"], dtype=float)
    print(f"mu_estimate min {np.nanmin(mu):.2f}; max |beta| "
          f"{math.degrees(float(np.max(np.abs(log.state['sideslip'])))):.2f} deg; "
          f"completed {log.completed}")
    first = next((i for i, s in enumerate(steps) if s[5] is not None and s[5] < 0.5 * s[4]),
                 None)
    if len(steps) != log.steps:
        print(f"the estimator ran {len(steps)} times in {log.steps} steps: no trace")
        return 1
    if first is None:
        print("no evidence below half the estimate")
        return 0
    t, vy_true = log.state["t_s"], log.state["vy"]
    print("| t s | αf' deg | αr' deg | v_y seen | v_y true | a_y seen | μ̂ | evidence "
          "| ask/(μ̂ m g) |")
    print("|---|---|---|---|---|---|---|---|---|")
    for k in range(max(0, first - 3), min(len(steps), first + 4)):
        af, ar, vy, ay, mu_k, ev, ask = steps[k]
        evs = "—" if ev is None else f"{ev:.3f}"
        print(f"| {t[k]:.2f} | {af:+.2f} | {ar:+.2f} | {vy:+.3f} | {vy_true[k]:+.3f} | "
              f"{ay:+.2f} | {mu_k:.2f} | {evs} | {ask:.2f} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
