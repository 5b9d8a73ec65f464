"""The fair allocation baseline (``production``): what a car already does, against eq. (27)
and the stated axle shares; and the MPC starting from the yaw moment delivered."""

import math

import numpy as np
import pytest

from fourws_bringup.core.conditions import condition_from_mapping, node_parameters
from fourws_mpc.core.config import MpcConfig
from fourws_mpc.core.controller import MpcController, VehicleSample
from fourws_mpc.core.model import InputIdx
from fourws_mpc.core.reference import Reference
from fourws_torque_alloc.core.allocation import (
    AllocatorConfig,
    allocate,
    yaw_moment_nm,
)

CFG = AllocatorConfig()
FZ = np.array([2000.0, 1700.0, 1900.0, 1600.0])
FY = np.zeros(4)
MU = np.array([0.9, 0.3, 0.9, 0.3])


@pytest.mark.parametrize("t,mz", [(400.0, 0.0), (-600.0, 0.0), (-300.0, 500.0),
                                  (200.0, -800.0)])
def test_production_meets_eq27_and_splits_by_the_stated_shares(t, mz):
    res = allocate("production", t, mz, FZ, FY, MU, CFG)
    tq = res.torque_nm
    assert float(np.sum(tq)) == pytest.approx(t, abs=1e-9)
    assert yaw_moment_nm(tq, CFG) == pytest.approx(mz, abs=1e-9)
    drive_front = CFG.cg_to_rear_axle_m / (CFG.cg_to_front_axle_m + CFG.cg_to_rear_axle_m)
    for front, rear in ((0, 2), (1, 3)):
        side = tq[front] + tq[rear]
        share = drive_front if side >= 0 else CFG.brake_balance_front
        assert tq[front] == pytest.approx(share * side, abs=1e-9)
    assert res.status == "ok"


def test_production_ignores_the_road_where_the_load_ratio_split_follows_it():
    """On split μ the paper's split puts the low-μ side's torque where the grip is; the
    fair baseline keeps its fixed shares (it does not know μ, as a car's brake balance)."""
    prod = allocate("production", -800.0, 0.0, FZ, FY, MU, CFG).torque_nm
    opt = allocate("optimal", -800.0, 0.0, FZ, FY, MU, CFG).torque_nm
    assert prod[0] / (prod[0] + prod[2]) == pytest.approx(CFG.brake_balance_front)
    assert not np.allclose(prod, opt)


def test_a_condition_carries_allocator_overrides_to_the_allocator_only():
    c = condition_from_mapping({"name": "x", "allocator_overrides": {"method": "production"}})
    assert not c.ideal
    p = node_parameters(c)
    assert p["allocator_node"]["method"] == "production"
    assert "method" not in p["mpc_node"]


def _ref(v):
    x = np.arange(-20.0, 300.0, 0.05)
    return Reference.from_arrays(x, np.zeros_like(x), np.zeros_like(x), np.zeros_like(x),
                                 np.full_like(x, v))


def test_the_mpc_starts_from_the_yaw_moment_delivered():
    v = 16.7
    ctrl = MpcController(MpcConfig(terminal_cost="lqr"))
    ref = _ref(v)
    res = ctrl.step(0.0, VehicleSample(0.0, 0.3, 0.05, v, 0.0, 0.1), ref, mu=0.9)
    assert res.yaw_moment != 0.0
    delivered = 0.25 * res.yaw_moment
    ctrl.report_delivered(delivered)
    assert ctrl.u_prev[InputIdx.MZ] == delivered
    assert ctrl.sent.registers[0][InputIdx.MZ] == delivered
    # the next increment is bounded from the delivered value, not from the demand
    nxt = ctrl.step(0.01, VehicleSample(0.167, 0.3, 0.05, v, 0.0, 0.1), ref, mu=0.9)
    assert abs(nxt.yaw_moment - delivered) <= ctrl.cfg.max_dyaw_moment_nm + 1e-9
    with pytest.raises(ValueError, match="not finite"):
        ctrl.report_delivered(math.nan)
    assert ctrl.u_prev[InputIdx.MZ] == nxt.yaw_moment


def test_a_controller_without_dyc_keeps_a_zero_yaw_moment():
    ctrl = MpcController(MpcConfig(use_dyc=False, terminal_cost="lqr"))
    ctrl.report_delivered(500.0)
    assert ctrl.u_prev[InputIdx.MZ] == 0.0
