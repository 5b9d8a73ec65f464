"""Closed loop on the plant core (slow): the paper's scenarios in both worlds, with their
lead-out, and APCHA's horizon behaviour."""

from pathlib import Path

import numpy as np
import pytest
import yaml

from fourws_bringup.core.closed_loop import run_closed_loop
from fourws_bringup.core.conditions import load_condition
from fourws_common.resources import config_dir

ROOT = Path(__file__).resolve().parents[2]
PRESETS = ("mpc_fws", "mpc_4ws", "improved", "ampc_4ws", "ampc_4ws_dyc", "lqr_ff",
           "improved_np30")   # the last beyond the paper (N_p 30)
#: the paper scenarios with a 30 s straight lead-out, and where the paper's run ends (X, m)
BENCH = {"dlc_60_mu05": (ROOT / "benchmarks/scenarios/bench_dlc_60_mu05.yaml", 173.0),
         "dlc_90_mu06": (ROOT / "benchmarks/scenarios/bench_dlc_90_mu06.yaml", 250.0)}


#: 26 s and 31 s: the manoeuvre (10.4 s at 60 km/h) and 15 s or 20 s of the 30 s lead-out
#: (the bench runs all of it)
IDEAL_STEPS, REALISTIC_STEPS = 2600, 3100


def _ran_out(m: dict) -> bool:
    """The run lasted its step budget: not aborted (left the road, spun) before."""
    return m["reason"].startswith("max_steps") and not m["reason"].startswith("aborted")


def _lead_out_rms(log, x_end: float, window_s: float = 5.0) -> np.ndarray:
    """Yaw-rate RMS (rad/s, the plant's truth) over consecutive windows of the lead-out (X
    beyond the paper's end of run)."""
    t, r = log.state["t_s"], log.state["yaw_rate"]
    t0 = t[np.argmax(log.state["x"] > x_end)]
    edges = np.arange(t0, t[-1] - window_s + 1e-9, window_s)
    return np.array([np.sqrt(np.mean(r[(t >= a) & (t < a + window_s)] ** 2)) for a in edges])


@pytest.mark.slow
@pytest.mark.parametrize("scenario", sorted(BENCH))
def test_ideal_world_rear_steer_tracks_better_with_less_sideslip_and_the_lead_out_decays(scenario):
    """The paper's setting (truth in, no delay): every preset runs the manoeuvre and 15 s of
    lead-out without abort; the presets with
    rear steer hold the path closer than the front-steer controllers and within a third of
    their sideslip (the rear axle steers the sideslip away; front steer alone must yaw the
    car into the lane: with the same cost structure on its own scaling, `mpc_fws` holds
    2.6 mm against `mpc_4ws`'s 1.7 at 60 km/h) and within the paper's 0.089 m; on the
    lead-out (15 s of it) the yaw rate dies out: its last 5 s RMS is below 1 % of the first
    5 s RMS."""
    path, x_end = BENCH[scenario]
    logs = {c: run_closed_loop(str(path), c, IDEAL_STEPS) for c in PRESETS}
    m = {c: log.metrics() for c, log in logs.items()}
    assert all(_ran_out(m[c]) for c in PRESETS), m
    front = min(m[c]["max_abs_lateral_error_m"] for c in ("mpc_fws", "lqr_ff"))
    beta = min(m[c]["max_abs_sideslip_deg"] for c in ("mpc_fws", "lqr_ff"))
    for c in ("mpc_4ws", "improved", "ampc_4ws", "ampc_4ws_dyc"):
        assert m[c]["max_abs_lateral_error_m"] < front, (c, m[c], front)
        assert m[c]["max_abs_sideslip_deg"] < beta / 3.0, (c, m[c], beta)
    assert m["improved"]["max_abs_lateral_error_m"] < 0.089
    for c, log in logs.items():
        rms = _lead_out_rms(log, x_end)
        assert len(rms) >= 3 and rms[-1] < 0.01 * rms[0], (c, rms)


@pytest.mark.slow
def test_table_8_the_yaw_moment_is_used_and_the_allocation_ties():
    """Table 8 on dlc_60_mu05: the DYC presets command a yaw moment and AMPC-4WS none (about a
    hundred N·m: 113 with the level penalty κ 0.0088, 231 with 0.0043); with rear steer
    already holding the path to a millimetre, the moment moves
    max |e_Y| by less than 1 mm either way (the paper: 171 → 124 mm, a car without the rear
    axle's authority). Rule-based and load-ratio allocation of that moment tie (e_Y within
    0.1 mm, sideslip within 0.01°): they only split each side's torque front/rear differently."""
    m, mz = {}, {}
    for c in ("improved", "ampc_4ws_dyc", "ampc_4ws"):
        log = run_closed_loop("dlc_60_mu05", c)
        m[c], mz[c] = log.metrics(), float(np.abs(log.mpc["yaw_moment"]).max())
        assert m[c]["completed"], m[c]
    assert mz["ampc_4ws"] == 0.0 and 30.0 < mz["improved"] < 1500.0, mz
    e = {c: m[c]["max_abs_lateral_error_m"] for c in m}
    assert abs(e["improved"] - e["ampc_4ws"]) < 1e-3, e
    for key in ("max_abs_lateral_error_m", "rmse_lateral_error_m"):
        assert m["improved"][key] == pytest.approx(m["ampc_4ws_dyc"][key], abs=1e-4), (key, m)
    assert m["improved"]["max_abs_sideslip_deg"] == pytest.approx(          # hundredths of a
        m["ampc_4ws_dyc"]["max_abs_sideslip_deg"], abs=0.01)                 # degree


@pytest.mark.slow
@pytest.mark.parametrize("scenario, seed, condition", [
    ("dlc_60_mu05", 0, "robustness.yaml#all"), ("dlc_90_mu06", 1, "robustness.yaml#all"),
    ("dlc_60_mu05", 2, "robustness.yaml#all_ekf")])
def test_realistic_world_every_preset_completes_and_the_lead_out_does_not_grow(scenario, seed,
                                                                               condition):
    """Under the bench's "all" (localisation and IMU noise, 1 period of delay, 40 ms of
    steering dead time, estimated tyre forces; the delays known to the controllers), and
    under "all" with the localisation filter in the loop (beyond the paper): every
    preset runs the paper scenario and 20 s of its lead-out without abort (the bench runs
    all 30 s over five seeds). The noise keeps exciting the loop,
    so the yaw rate settles to a noise-driven level instead of zero: a slowly growing
    oscillation would raise it, so the RMS of the last 10 s may not exceed 1.25 × the RMS
    of the 10 s before."""
    path, x_end = BENCH[scenario]
    cond = load_condition(str(ROOT / "benchmarks" / condition), seed=seed)
    assert cond.known_delays and cond.delay_periods == 1
    assert cond.localisation == ("ekf" if condition.endswith("ekf") else "none")
    for c in PRESETS:
        log = run_closed_loop(str(path), c, REALISTIC_STEPS, condition=cond)
        m = log.metrics()
        assert _ran_out(m), (c, m)
        rms = _lead_out_rms(log, x_end)
        late, before = np.sqrt(np.mean(rms[-2:] ** 2)), np.sqrt(np.mean(rms[-4:-2] ** 2))
        assert late <= 1.25 * before, (c, rms)


@pytest.mark.slow
def test_apcha_horizons_grow_on_large_errors_and_return_to_baseline(tmp_path: Path):
    base = config_dir("fourws_sim") / "scenarios" / "dlc_60_mu05.yaml"
    sc = yaml.safe_load(base.read_text(encoding="utf-8"))
    sc["name"] = "dlc_60_mu05_offset"
    sc["initial"] = {"x_m": 0.0, "y_m": 0.12, "yaw_deg": 0.0}  # e_s ≈ 0.24 ∈ (ε1, 2ε1]
    path = tmp_path / "offset.yaml"
    path.write_text(yaml.safe_dump(sc), encoding="utf-8")
    log = run_closed_loop(str(path), "improved")
    assert log.completed, log.reason
    n_p, n_c = log.mpc["np"], log.mpc["nc"]
    assert list(n_p[:4]) == [14, 16, 18, 20]           # towards N_p^t = 20, ΔN_p per period
    assert n_p.max() >= 20 and n_c.max() >= 8          # grown on the large error
    tail = slice(-200, None)                           # last 2 s: small errors
    assert np.all(n_p[tail] == 12) and np.all(n_c[tail] <= 6)
    assert np.abs(log.mpc["lateral_error"][tail]).max() < 0.02
    assert not log.mpc["fallback"][tail].any()
