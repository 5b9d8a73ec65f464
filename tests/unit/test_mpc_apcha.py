"""APCHA, eq. (7)-(15): every branch of eq. (13)-(14) and every clamp of eq. (15)."""

import math

import numpy as np
import pytest

from fourws_mpc.core.apcha import ApchaParams, apcha, input_rate, integrated_error, np_target

P = ApchaParams(np_rate_limit=False)
PR = ApchaParams(np_rate_limit=True)
Z = np.zeros(3)


def test_integrated_error_eq7():
    p = ApchaParams(lam=0.4)
    assert integrated_error(0.25, math.radians(-4.0), p) == pytest.approx(0.5 + 0.4 * 0.5)
    assert integrated_error(-0.25, 0.0, p) == pytest.approx(0.5)


def test_input_rate_eq9_is_infinity_norm_of_normalised_increment():
    du = np.array([math.radians(0.4), math.radians(-0.45), 60.0])
    assert input_rate(du, P) == pytest.approx(0.75)
    assert input_rate(np.array([0.0, 0.0, -300.0]), P) == pytest.approx(1.0)


@pytest.mark.parametrize("e_s,expected", [
    (0.0, 12), (0.2, 12),            # e_s ≤ ε1: N_p,min + ΔN_p
    (0.2001, 20), (0.4, 20),         # ε1 < e_s ≤ 2ε1: ⌊(30 + 10)/2⌋
    (0.4001, 28), (5.0, 28),         # e_s > 2ε1: N_p,max − ΔN_p
])
def test_np_target_branches_eq13(e_s, expected):
    assert np_target(e_s, P) == expected


def test_k_e_eq8_and_first_step():
    r = apcha(0.3, None, Z, 12, 6, P)
    assert r.k_e == 0.0
    r = apcha(0.3, 0.29, Z, 12, 6, P)
    assert r.k_e == pytest.approx(1.0)


def test_nc_increases_when_error_rate_is_high():
    r = apcha(0.1, 0.1 - 0.006, Z, 12, 5, P)          # k_e = 0.6 > ε2
    assert (r.n_p, r.n_c, r.nc_target) == (12, 6, 6)


def test_nc_decreases_when_input_rate_is_high():
    du = np.array([math.radians(0.4), 0.0, 0.0])      # k_u = 0.5 > ε3
    r = apcha(0.1, 0.1, du, 12, 6, P)
    assert (r.n_c, r.nc_target) == (5, 5)


def test_error_rate_branch_wins_over_input_rate_branch():
    du = np.array([math.radians(0.4), 0.0, 0.0])
    r = apcha(0.1, 0.09, du, 12, 5, P)                # k_e = 1 > ε2 and k_u > ε3
    assert r.n_c == 6


def test_nc_holds_otherwise():
    du = np.array([math.radians(0.2), 0.0, 0.0])      # k_u = 0.25 ≤ ε3
    r = apcha(0.1, 0.098, du, 12, 5, P)               # k_e = 0.2 ≤ ε2
    assert r.n_c == 5 and r.nc_target == 5


def test_nc_clamped_to_half_np_eq15():
    r = apcha(0.1, 0.0, Z, 12, 6, P)                  # 6 + 1 = 7 > ⌊12/2⌋
    assert r.nc_target == 7 and r.n_c == 6


def test_nc_clamped_to_third_np_eq15():
    du = np.array([0.0, 0.0, 300.0])
    r = apcha(0.1, 0.1, du, 12, 4, P)                 # 4 − 1 = 3 < ⌊12/3⌋
    assert r.nc_target == 3 and r.n_c == 4


def test_nc_clamped_to_nc_max_eq15():
    r = apcha(1.0, 0.0, Z, 28, 10, P)                 # 11 > N_c,max, ⌊28/2⌋ = 14
    assert r.nc_target == 11 and r.n_c == 10


def test_nc_clamped_to_nc_min_eq15():
    p = ApchaParams(np_rate_limit=False, np_min=6, np_step=0, nc_min=3)
    du = np.array([0.0, 0.0, 300.0])
    r = apcha(0.0, 0.0, du, 6, 3, p)                  # 3 − 1 = 2 < N_c,min; ⌊6/3⌋ = 2
    assert r.nc_target == 2 and r.n_c == 3


def test_np_clamped_to_limits_eq15():
    p = ApchaParams(np_rate_limit=False, np_min=10, np_max=30, np_step=25)
    assert apcha(0.0, 0.0, Z, 12, 6, p).n_p == 30     # 10 + 25 = 35 → N_p,max
    assert apcha(1.0, 1.0, Z, 12, 6, p).n_p == 10     # 30 − 25 = 5 → N_p,min


def test_np_rate_limit_moves_by_step():
    r = apcha(1.0, 1.0, Z, 12, 6, PR)                 # target 28
    assert (r.np_target, r.n_p) == (28, 14)
    r = apcha(0.0, 0.0, Z, 20, 7, PR)                 # target 12
    assert r.n_p == 18


def test_literal_nc_reading_uses_third_of_np_target():
    p = ApchaParams(np_rate_limit=False, nc_base="np_third")
    r = apcha(0.3, 0.3, Z, 12, 6, p)                  # N_p^t = 20 → N_c^i = 6
    assert (r.n_p, r.n_c) == (20, 6)
    r = apcha(0.3, 0.29, Z, 20, 6, p)                 # k_e > ε2 → 7
    assert r.n_c == 7


def test_paper_behaviour_grow_then_return_to_baseline():
    """Large errors: N_p 12 → 20, N_c 6 → 10; small errors: back to 12 / 6 (section 4.1)."""
    n_p, n_c, es_prev = 12, 6, 0.0
    es_seq = [0.21 + 0.01 * k for k in range(15)]     # rising error in (ε1, 2ε1]
    for es in es_seq:
        r = apcha(es, es_prev, Z, n_p, n_c, PR)
        n_p, n_c, es_prev = r.n_p, r.n_c, es
    assert (n_p, n_c) == (20, 10)
    for _ in range(10):
        r = apcha(0.05, 0.05, Z, n_p, n_c, PR)
        n_p, n_c = r.n_p, r.n_c
    assert (n_p, n_c) == (12, 6)
